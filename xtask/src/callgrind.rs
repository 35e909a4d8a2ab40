//! Running a program under `valgrind --tool=callgrind`, for `bench` and `timing`.

use std::path::Path;
use std::process::{Command, Stdio};

/// Fails, naming the package, when valgrind is not installed.
pub fn check() -> Result<(), String> {
    match Command::new("valgrind")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
    {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("`valgrind --version` failed ({s})")),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(
            "valgrind is not installed; the instruction counts need it: `apt-get install valgrind` \
             (scripts/test.sh installs it)"
                .to_owned(),
        ),
        Err(e) => Err(format!("cannot run valgrind: {e}")),
    }
}

/// Runs `program` with `args` in `root` under callgrind (with callgrind `options`), writing its
/// profile to `out_file`; returns the program's standard output.
pub fn run(
    root: &Path,
    out_file: &Path,
    options: &[&str],
    program: &Path,
    args: &[&str],
) -> Result<String, String> {
    check()?;
    let out = Command::new("valgrind")
        .current_dir(root)
        .arg("--tool=callgrind")
        .args(options)
        .arg(format!("--callgrind-out-file={}", out_file.display()))
        .arg(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run valgrind: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "{} {} failed under callgrind: {}",
            program.display(),
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}
