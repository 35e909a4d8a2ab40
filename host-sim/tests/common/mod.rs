//! What the command-line tests share: the binary, scratch files, the success check.

use std::path::PathBuf;
use std::process::{Command, Output};

/// The `psmpa-sim` binary of this build.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_psmpa-sim"))
}

/// A scratch file with `content`, unique to the test binary.
pub fn file(name: &str, content: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("psmpa-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path
}

/// The command exited with status 0; its stderr otherwise.
pub fn assert_success(out: &Output) {
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
