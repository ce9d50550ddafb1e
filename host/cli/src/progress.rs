//! The one progress bar style of the `ocm` commands.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over `n` steps labelled `what`, with elapsed time and estimate.
pub fn bar(n: usize, what: &str) -> ProgressBar {
    let b = ProgressBar::new(n as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} {bar:40} {pos}/{len} [{elapsed_precise} < {eta}]")
    {
        b.set_style(style);
    }
    b.set_message(what.to_string());
    b
}

/// [`bar`] when `show`, else a hidden bar (for `--json` runs).
pub fn bar_if(n: usize, what: &str, show: bool) -> ProgressBar {
    if show {
        bar(n, what)
    } else {
        ProgressBar::hidden()
    }
}
