//! The flight recordings a firmware streams, gathered from its log and replayed on the host.
//!
//! A firmware sends its recording as defmt lines `rec [bytes]` (over semihosting in QEMU, over
//! RTT on a board): a header starts each run's recording, frames follow. Each recording is
//! kept as a file and replayed by `psmpa_sim::replay`, which compares every decision.

use std::path::{Path, PathBuf};

use embassy_time::Duration;
use psmpa_sim::replay;

/// How much earlier or later than recorded a replayed event may come from a chip's recording:
/// the chip computes for a few ticks where the host takes none (`replay::replay`).
pub const CHIP_LAG: Duration = Duration::from_millis(2);

/// What replaying a log's recordings found.
#[derive(Debug, Default)]
pub struct Replays {
    /// Recordings replayed.
    pub runs: usize,
    /// Decisions compared in all.
    pub decisions: usize,
    /// Bytes recorded in all.
    pub bytes: usize,
    /// Recorded time in all, ms.
    pub recorded_ms: u64,
    /// The most an equal event came earlier or later than recorded, ms.
    pub skew_ms: u64,
    /// Each recording that did not replay equal: why.
    pub failures: Vec<String>,
}

/// Keeps each recording of `log` in `dir` and replays it on the host: `NAME.rec` where `name`
/// is given, else `SCENARIO.ARCH.rec` (`-N` after the first).
pub fn replay_log(log: &str, dir: &Path, lag: Duration, name: Option<&str>) -> Replays {
    let mut result = Replays::default();
    let recs = match replay::from_log(log) {
        Ok(r) => r,
        Err(e) => {
            result.failures.push(e);
            return result;
        }
    };
    if let Err(e) = std::fs::create_dir_all(dir) {
        result
            .failures
            .push(format!("cannot keep recordings in {}: {e}", dir.display()));
        return result;
    }
    for (i, bytes) in recs.iter().enumerate() {
        let file = |stem: &str| {
            let n = if i > 0 && name.is_some() {
                format!("-{i}")
            } else {
                String::new()
            };
            dir.join(format!("{stem}{n}.rec"))
        };
        let mut path = file(name.unwrap_or("run"));
        let read = replay::read(&path, bytes);
        if let (Ok(rec), None) = (&read, name) {
            path = file(&rec.name());
        }
        // Kept for reading whatever the replay says: `psmpa-sim replay FILE` runs it again.
        if let Err(e) = std::fs::write(&path, bytes) {
            result
                .failures
                .push(format!("cannot write {}: {e}", path.display()));
        }
        result.runs += 1;
        result.bytes += bytes.len();
        let outcome = read.and_then(|rec| {
            result.recorded_ms += rec.frames.last().map_or(0, |f| f.ticks);
            replay::replay(&rec, None, lag).map(|(r, _)| r)
        });
        match outcome {
            Ok(r) if !r.diverged => {
                result.decisions += r.decisions;
                result.skew_ms = result.skew_ms.max(r.skew_ms);
            }
            Ok(r) => result
                .failures
                .push(format!("{}: {}", path.display(), r.text().trim_end())),
            Err(e) => result.failures.push(e),
        }
    }
    result
}

/// Where the recordings of `label`'s runs are kept.
pub fn dir(label: &str) -> PathBuf {
    crate::firmware::root()
        .join("target/recordings")
        .join(label)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_gather_into_one_recording_a_header() {
        let log = "0.1 INFO  rec [80, 83, 77, 80, 65, 82, 69, 67, 1]\n0.1 INFO  w 0 0 0 0 0\n0.2 INFO  rec [7, 8]\n0.3 INFO  rec [80, 83, 77, 80, 65, 82, 69, 67, 2]\n";
        let recs = replay::from_log(log).unwrap();
        assert_eq!(recs.len(), 2);
        assert_eq!(recs[0][8..], [1, 7, 8]);
        assert_eq!(recs[1][8..], [2]);
        assert!(replay::from_log("0.1 INFO  rec [7]\n").is_err());
        assert!(replay::from_log("0.1 INFO  rec [700]\n").is_err());
    }
}
