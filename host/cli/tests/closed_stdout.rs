//! `ocm ... | head`: when the reader of standard output leaves, a run ends the way Unix tools
//! do (SIGPIPE), not with a panic and a backtrace.

use std::process::{Command, Stdio};

#[test]
fn a_closed_standard_output_ends_the_run_quietly() {
    let out_dir = std::env::temp_dir().join(format!("ocm-closed-stdout-{}", std::process::id()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_ocm"))
        .args(["peg", "demos", "--count", "1", "--json", "--out"])
        .arg(&out_dir)
        .env("RUST_BACKTRACE", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the ocm binary runs");
    // The reader leaves before the summary is printed.
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("ocm ends");
    let _ = std::fs::remove_dir_all(&out_dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.status.success(), "a lost summary is not a success");
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(out.status.signal(), Some(13), "{:?}: {err}", out.status);
    }
}
