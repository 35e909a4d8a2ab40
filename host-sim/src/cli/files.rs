//! The command line's reading and writing, in one place: an input that is not a small regular
//! file, an output that cannot be written, and a closed standard output all end in one line
//! and an exit status; no output file is ever left half-written.

use std::fs::{File, Metadata, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use tempfile::NamedTempFile;

/// Temporary files of the outputs not yet committed: removed when the process is interrupted.
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// On Ctrl-C or SIGTERM, removes the temporary files of outputs not yet committed and exits
/// with status 130, so that an interrupted command leaves no `.part` file. Call once, first.
/// (The handler runs on its own thread, not in the signal's context: it may lock and unlink.)
pub fn clean_up_on_interrupt() {
    let _ = ctrlc::set_handler(|| {
        if let Ok(pending) = PENDING.lock() {
            for path in pending.iter() {
                let _ = std::fs::remove_file(path);
            }
        }
        std::process::exit(130);
    });
}

/// A temporary file listed in [`PENDING`] while it lives.
struct Registered(PathBuf);

impl Registered {
    fn new(path: &Path) -> Self {
        if let Ok(mut pending) = PENDING.lock() {
            pending.push(path.to_path_buf());
        }
        Self(path.to_path_buf())
    }
}

impl Drop for Registered {
    fn drop(&mut self) {
        if let Ok(mut pending) = PENDING.lock() {
            pending.retain(|p| *p != self.0);
        }
    }
}

/// A file of the command's own that is no output (an image a bench boots, a scratch file):
/// removed when dropped, whatever ended its use (an error, a panic), and when the process is
/// interrupted ([`clean_up_on_interrupt`]).
pub struct Scratch {
    path: PathBuf,
    _registered: Registered,
}

impl Scratch {
    /// Takes charge of the file at `path` (made or not yet).
    pub fn new(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            _registered: Registered::new(path),
        }
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

pub use psmpa_model::check::{MAX_INPUT, read_input, read_limited};

/// Why a command stopped before the end.
#[derive(Debug)]
pub enum Stop {
    /// Bad input, or an output that could not be written: exit 2 with this line.
    Bad(String),
    /// A run that could not be completed (it deadlocked): exit 1 with this line.
    Internal(String),
    /// Standard output was closed by its reader (`| head`): nothing is lost that was asked
    /// for, so the command ends quietly with status 0.
    ClosedPipe,
    /// `plan` found no plan (and said so): exit 1.
    NoPlan,
    /// The machine could not give what the command needs (a thread, its stack): exit 3 with
    /// this line. Not the input's fault: the same command may run where more is allowed.
    Resource(String),
}

impl Stop {
    /// Bad input, or an output that could not be written.
    pub fn bad(message: impl ToString) -> Self {
        Self::Bad(message.to_string())
    }

    /// A run that could not be completed.
    pub fn internal(message: impl ToString) -> Self {
        Self::Internal(message.to_string())
    }
}

/// Writes `bytes` to standard output: a closed pipe is [`Stop::ClosedPipe`], any other
/// failure (`>/dev/full`) one line.
pub fn print(bytes: &[u8]) -> Result<(), Stop> {
    let mut out = io::stdout().lock();
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .map_err(|e| match e.kind() {
            io::ErrorKind::BrokenPipe => Stop::ClosedPipe,
            _ => Stop::bad(format!("standard output: cannot write: {e}")),
        })
}

/// Where an output's bytes go until it is committed.
enum Sink {
    /// A temporary file beside the target, renamed over it when complete.
    Staged(BufWriter<NamedTempFile>),
    /// A device or pipe that already exists (`/dev/null`, `>(gzip > t.gz)`): written in
    /// place, as there is nothing to rename.
    Direct(BufWriter<File>),
}

/// An output file being written. Nothing appears at its path until [`commit`] succeeds; a
/// write error is kept and reported at [`commit`], and dropping it uncommitted leaves the
/// target as it was.
///
/// [`commit`]: Output::commit
pub struct Output {
    path: PathBuf,
    /// The path as the user gave it (before following a symbolic link), for messages.
    given: PathBuf,
    sink: Sink,
    error: Option<io::Error>,
    /// Raised at the first write error ([`Output::alarm`]).
    alarm: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Written through standard output: the report goes to standard error.
    to_stdout: bool,
    /// A pipe whose reader has gone: the rest is dropped.
    closed: bool,
    /// Dropped last, after the temporary file is renamed or removed.
    _pending: Option<Registered>,
}

impl Output {
    /// Starts writing the output at `path`; fails at once, with one line, when it could
    /// never be written (no such folder, a directory, no permission).
    pub fn create(path: &Path) -> Result<Self, String> {
        let fail = |e: io::Error| format!("{}: cannot write: {e}", path.display());
        // A character device, FIFO or socket (`/dev/null`, a pipe, `>(gzip)` as `/dev/fd/63`,
        // `/dev/stdout` on a terminal) is written in place, appending, as there is nothing to
        // rename; the kernel follows `/dev/fd` and `/proc` links to it. Any regular file,
        // whatever path names it, is replaced whole.
        let target = match std::fs::metadata(path) {
            Ok(meta) if meta.is_dir() => {
                return Err(format!("{}: is a directory, not a file", path.display()));
            }
            // Standard output itself (`--trace /dev/stdout`, to a file, a pipe or a terminal):
            // written through it, and the report goes to standard error, so that the output
            // arrives whole (a recording stays a recording).
            Ok(meta) if stdout_meta().is_some_and(|out| same_file(&out, &meta)) => {
                use std::os::fd::AsFd as _;
                // A file named by its own path that the shell also opened for standard output
                // (`--trace t.csv > t.csv`): the shell has emptied it, and two writers with
                // their own offsets would overwrite each other.
                if meta.is_file() && !is_stdout_alias(path) {
                    return Err(format!(
                        "{}: is standard output's file too (> {0}): the report and the output \
                         cannot share it; name another file (or write the output to /dev/stdout)",
                        path.display()
                    ));
                }
                let fd = io::stdout().as_fd().try_clone_to_owned().map_err(fail)?;
                return Ok(Self {
                    path: path.to_path_buf(),
                    given: path.to_path_buf(),
                    sink: Sink::Direct(BufWriter::new(File::from(fd))),
                    error: None,
                    alarm: None,
                    to_stdout: true,
                    closed: false,
                    _pending: None,
                });
            }
            Ok(meta) if !meta.is_file() => {
                let file = OpenOptions::new().append(true).open(path).map_err(fail)?;
                return Ok(Self {
                    path: path.to_path_buf(),
                    given: path.to_path_buf(),
                    sink: Sink::Direct(BufWriter::new(file)),
                    error: None,
                    alarm: None,
                    to_stdout: false,
                    closed: false,
                    _pending: None,
                });
            }
            // Through a symbolic link to the file it names, as `>` does, even one that names a
            // file not made yet: renaming over the link would lose it.
            _ => follow(path).map_err(fail)?,
        };
        let sink = match std::fs::metadata(&target) {
            Ok(meta) if meta.is_dir() => {
                return Err(format!("{}: is a directory, not a file", path.display()));
            }
            // Read-only: `>` and `cp` refuse to write it, and so does this.
            Ok(meta) if meta.permissions().readonly() => {
                return Err(format!(
                    "{}: is read-only: not replaced (make it writable, or name another file)",
                    path.display()
                ));
            }
            existing => {
                let dir = match target.parent() {
                    Some(d) if !d.as_os_str().is_empty() => d,
                    _ => Path::new("."),
                };
                let name = target
                    .file_name()
                    .ok_or_else(|| format!("{}: not a file name", path.display()))?;
                let mut builder = tempfile::Builder::new();
                let prefix = format!(".{}.", name.to_string_lossy());
                builder.prefix(&prefix).suffix(".part");
                #[cfg(unix)]
                {
                    // A file replaced keeps its mode, as `>` keeps it; a new one is 0666 less
                    // the umask, as any new file (a temporary file is 0600).
                    use std::os::unix::fs::PermissionsExt as _;
                    let mode = existing.as_ref().map_or(0o666, |m| m.permissions().mode());
                    builder.permissions(std::fs::Permissions::from_mode(mode & 0o7777));
                }
                let file = builder.tempfile_in(dir).map_err(|e| {
                    // tempfile ends its message with the temporary path (`... at path
                    // "/d/.x.part"`): name the path the user gave instead.
                    let message = e.to_string();
                    let cause = message.split(" at path ").next().unwrap_or(&message);
                    format!("{}: cannot write: {cause}", path.display())
                })?;
                #[cfg(unix)]
                if let Ok(meta) = &existing {
                    // And its owner and group where the user may keep them (the owner only
                    // as root; a group the user belongs to): else the user's, as for `cp`.
                    use std::os::unix::fs::MetadataExt as _;
                    let _ = std::os::unix::fs::fchown(file.as_file(), Some(meta.uid()), None);
                    let _ = std::os::unix::fs::fchown(file.as_file(), None, Some(meta.gid()));
                }
                Sink::Staged(BufWriter::new(file))
            }
        };
        let pending = match &sink {
            Sink::Staged(w) => Some(Registered::new(w.get_ref().path())),
            Sink::Direct(_) => None,
        };
        Ok(Self {
            path: target,
            given: path.to_path_buf(),
            sink,
            error: None,
            alarm: None,
            to_stdout: false,
            closed: false,
            _pending: pending,
        })
    }

    /// Raises `flag` at the output's first write error, so that the run writing it can stop
    /// at once (the error itself is reported by [`Output::finish`]).
    pub fn alarm(&mut self, flag: std::sync::Arc<std::sync::atomic::AtomicBool>) {
        if self.error.is_some() {
            flag.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        self.alarm = Some(flag);
    }

    /// Keeps a write's failure for [`Output::finish`] and raises the alarm; a pipe whose
    /// reader went away (`| head`) is no failure: what it was sent was read, the rest is
    /// dropped, as for standard output.
    fn fail(&mut self, e: io::Error) {
        if e.kind() == io::ErrorKind::BrokenPipe && matches!(self.sink, Sink::Direct(_)) {
            self.closed = true;
            return;
        }
        self.error.get_or_insert(e);
        if let Some(flag) = &self.alarm {
            flag.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }

    /// The path the output is for.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes everything buffered; the first error, if any, as one line.
    pub fn finish(&mut self) -> Result<(), String> {
        let flushed = match &mut self.sink {
            Sink::Staged(w) => w.flush(),
            Sink::Direct(w) => w.flush(),
        };
        if let Err(e) = flushed {
            self.fail(e);
        }
        match &self.error {
            Some(e) => Err(format!("{}: cannot write: {e}", self.path.display())),
            None => Ok(()),
        }
    }

    /// Puts the complete output in place.
    pub fn commit(mut self) -> Result<(), String> {
        self.finish()?;
        let fail = |e: io::Error| format!("{}: cannot write: {e}", self.path.display());
        match self.sink {
            Sink::Staged(w) => {
                let file = w.into_inner().map_err(|e| fail(e.into_error()))?;
                file.persist(&self.path)
                    .map(drop)
                    .map_err(|e| fail(e.error))
            }
            Sink::Direct(_) => Ok(()),
        }
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        // After a failure the rest is dropped here and the failure reported at `finish`: a
        // streaming writer must not stop the run it records.
        if self.error.is_some() || self.closed {
            return Ok(buf.len());
        }
        let written = match &mut self.sink {
            Sink::Staged(w) => w.write_all(buf),
            Sink::Direct(w) => w.write_all(buf),
        };
        if let Err(e) = written {
            self.fail(e);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Writes complete outputs: every one is flushed first, so a full disk fails before any is
/// put in place, then each is renamed over its target. When all are in place, one line on
/// stderr names each file written (`psmpa-sim: wrote t.csv`); a device or pipe written in
/// place is not named, and a failure prints only its own line.
pub fn commit_all(outputs: impl IntoIterator<Item = Output>) -> Result<(), String> {
    let mut outputs: Vec<Output> = outputs.into_iter().collect();
    for o in &mut outputs {
        o.finish()?;
    }
    let written: Vec<PathBuf> = outputs
        .iter()
        .filter(|o| matches!(o.sink, Sink::Staged(_)))
        .map(|o| o.given.clone())
        .collect();
    outputs.into_iter().try_for_each(Output::commit)?;
    let mut stderr = io::stderr().lock();
    for path in written {
        let shown = path.display().to_string();
        let _ = writeln!(
            stderr,
            "psmpa-sim: wrote {}",
            crate::json::printable(&shown)
        );
    }
    Ok(())
}

/// Prints `bytes` to standard output, then puts `outputs` in place: a command's files are
/// written only when its report could be. Every output is flushed first (a full disk fails
/// before anything is printed); when standard output fails (`>/dev/full`) the outputs are
/// dropped, their files left as they were (a device or pipe written in place has had its
/// bytes already). A reader that went away (`| head`) is not a failure: the files are still
/// put in place.
pub fn print_and_commit(
    bytes: &[u8],
    outputs: impl IntoIterator<Item = Output>,
) -> Result<(), Stop> {
    let mut outputs: Vec<Output> = outputs.into_iter().collect();
    for o in &mut outputs {
        o.finish().map_err(Stop::Bad)?;
    }
    let printed = if outputs.iter().any(|o| o.to_stdout) {
        let mut err = io::stderr().lock();
        let _ = err.write_all(bytes).and_then(|()| err.flush());
        Ok(())
    } else {
        print(bytes)
    };
    if let Err(Stop::Bad(_)) = printed {
        return printed;
    }
    commit_all(outputs).map_err(Stop::Bad)?;
    printed
}

/// Most symbolic links followed in a row (Linux's own limit).
const MAX_LINKS: usize = 40;

/// The path `path` names once its symbolic links are followed: the file itself where it
/// exists, else the path the last link points at (a dangling link names the file `>` would
/// make). A loop of links is an error, as it is to the shell.
fn follow(path: &Path) -> io::Result<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Ok(p);
    }
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        if !std::fs::symlink_metadata(&p).is_ok_and(|m| m.file_type().is_symlink()) {
            return Ok(p);
        }
        let next = std::fs::read_link(&p)?;
        // A relative link is relative to its own folder (`join` keeps an absolute one).
        p = p
            .parent()
            .map_or_else(|| next.clone(), |dir| dir.join(&next));
    }
    Err(io::Error::other("too many levels of symbolic links"))
}

/// The file a path names: symbolic links and `..` resolved where the file or its folder
/// exists, so two spellings of one file compare equal.
fn identity(path: &Path) -> PathBuf {
    let path = &follow(path).unwrap_or_else(|_| path.to_path_buf());
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    match (abs.parent(), abs.file_name()) {
        (Some(dir), Some(name)) => std::fs::canonicalize(dir).map_or(abs.clone(), |d| d.join(name)),
        _ => abs,
    }
}

/// Whether two existing paths are one file (hard links included).
fn same_inode(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    let _ = (a, b);
    false
}

/// Refuses, before anything runs, two outputs that name the same file (by path, link or hard
/// link), or an output that names the input: each `(what, path)` is an option (`--trace`) or
/// the input's role.
pub fn distinct(named: &[(&str, &Path)]) -> Result<(), String> {
    for (i, (a, pa)) in named.iter().enumerate() {
        let id = identity(pa);
        // Devices (`/dev/null`) may take several outputs.
        if std::fs::metadata(&id).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
            continue;
        }
        for (b, pb) in named.iter().skip(i + 1) {
            if identity(pb) == id || same_inode(pa, pb) {
                return Err(format!(
                    "{}: named by both {a} and {b}: give each output its own file",
                    pb.display()
                ));
            }
        }
    }
    Ok(())
}

/// What standard output is (a file, a pipe, a terminal), if it is open.
fn stdout_meta() -> Option<Metadata> {
    use std::os::fd::AsFd as _;
    let fd = io::stdout().as_fd().try_clone_to_owned().ok()?;
    File::from(fd).metadata().ok()
}

/// Whether `path` is a name of standard output itself rather than of a file.
fn is_stdout_alias(path: &Path) -> bool {
    ["/dev/stdout", "/dev/fd/1", "/proc/self/fd/1"]
        .iter()
        .any(|alias| path == Path::new(alias))
}

/// With `--json`, standard output carries one JSON object: refuses, before anything runs, an
/// output (`(option, path)`) that would write into it too (`--record /dev/stdout`).
pub fn not_into_json(named: &[(&str, &Path)]) -> Result<(), String> {
    let Some(out) = stdout_meta() else {
        return Ok(());
    };
    for (what, path) in named {
        if std::fs::metadata(path).is_ok_and(|m| same_file(&out, &m)) {
            return Err(format!(
                "{what} {}: standard output carries the --json report; write this output to a file",
                path.display()
            ));
        }
    }
    Ok(())
}

/// Whether two files' metadata are one file.
fn same_file(a: &Metadata, b: &Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        a.dev() == b.dev() && a.ino() == b.ino()
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Checks, before any work, that files can be written in folder `dir` once it is made: its
/// deepest existing ancestor is a folder this process may write in (a file is made and
/// removed there). Nothing is left behind.
pub fn writable_folder(dir: &Path) -> Result<(), String> {
    let mut at = dir;
    let existing = loop {
        match std::fs::metadata(at) {
            Ok(meta) if meta.is_dir() => break at,
            Ok(_) => {
                return Err(format!(
                    "{}: not a folder (--plots names a folder to write the plots into)",
                    at.display()
                ));
            }
            Err(_) => match at.parent() {
                Some(p) if !p.as_os_str().is_empty() => at = p,
                _ => break Path::new("."),
            },
        }
    };
    tempfile::Builder::new()
        .prefix(".psmpa-check.")
        .tempfile_in(existing)
        .map(drop)
        .map_err(|e| {
            let message = e.to_string();
            let cause = message.split(" at path ").next().unwrap_or(&message);
            format!("{}: cannot write: {cause}", dir.display())
        })
}

/// Makes folder `dir` and its missing parents; the topmost one made, to remove if the
/// command then fails (`None` when `dir` existed).
pub fn make_folder(dir: &Path) -> Result<Option<PathBuf>, String> {
    let mut top = None;
    let mut at = dir;
    while !at.exists() {
        top = Some(at.to_path_buf());
        match at.parent() {
            Some(p) if !p.as_os_str().is_empty() => at = p,
            _ => break,
        }
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("{}: cannot create the folder: {e}", dir.display()))?;
    Ok(top)
}
