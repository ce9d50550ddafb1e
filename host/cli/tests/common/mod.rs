//! Helpers shared by the CLI's end-to-end tests.

use std::process::Command;

/// Runs `cmd`, which must succeed, and parses its standard output as one JSON summary.
pub fn json_summary(cmd: &mut Command) -> serde_json::Value {
    let out = cmd.output().expect("the ocm binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON summary")
}
