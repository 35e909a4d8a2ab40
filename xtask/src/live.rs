//! `cargo xtask hil SCENARIO --view`: the chip's flight recording in psmpa-sim's live view,
//! frame by frame as its `rec` lines come off RTT (the stream `psmpa-sim view --frames -`
//! reads). A bad frame, a bad line or a stream cut mid-frame is an error line on the page and
//! standard error; the bench and the server go on either way.
//!
//! The bench plays two runs at a time: the view follows one run, the first to start while it
//! is free ([`claim`]), until that run ends.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use psmpa_sim::view::model::View;
use psmpa_sim::view::server;
use psmpa_sim::view::source::{FrameStream, Shared, fetch_tea_names, lock};

/// The view, once `--view` started it.
struct Live {
    shared: Arc<Shared>,
    /// A run is shown.
    busy: AtomicBool,
}

static LIVE: OnceLock<Live> = OnceLock::new();

/// Serves the view on 127.0.0.1:`port` from now on, on its own thread; prints its address.
pub fn start(port: u16) -> Result<(), String> {
    let mission = fetch_tea_names().map_err(|e| format!("the mission: {e:?}"))?;
    let listener = server::listen([127, 0, 0, 1].into(), port)?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    let shared = Arc::new(Shared {
        view: Mutex::new(View::new(mission)),
        pace: None,
        source: "the bench's chip (cargo xtask hil)".to_owned(),
    });
    let serving = Arc::clone(&shared);
    std::thread::Builder::new()
        .name("view-server".into())
        .spawn(move || {
            if let Err(e) = server::serve(listener, serving) {
                eprintln!("xtask hil: the view: {e}");
            }
        })
        .map_err(|e| format!("cannot start the view's server: {e}"))?;
    let live = Live {
        shared,
        busy: AtomicBool::new(false),
    };
    if LIVE.set(live).is_err() {
        return Err("the view was started twice".to_owned());
    }
    eprintln!("xtask hil: the chip's run live at http://{addr}/");
    Ok(())
}

/// The run the view shows: its frames go to the page; dropping it ends the run there (a frame
/// left half sent is said: the stream was cut).
pub struct Claim {
    shared: Arc<Shared>,
    stream: FrameStream,
}

/// The view for a run starting now: `None` when there is no view or it shows another run.
pub fn claim() -> Option<Claim> {
    let live = LIVE.get()?;
    if live.busy.swap(true, Ordering::AcqRel) {
        return None;
    }
    Some(Claim::new(Arc::clone(&live.shared)))
}

impl Claim {
    /// A run shown on `shared`, before its first byte.
    pub fn new(shared: Arc<Shared>) -> Self {
        Self {
            shared,
            stream: FrameStream::new(),
        }
    }

    /// The recording's next bytes, as the chip sent them.
    pub fn bytes(&mut self, bytes: &[u8]) {
        self.stream.feed(bytes, &self.shared);
    }

    /// A line of the chip's log that should have carried the recording and does not read.
    pub fn error(&self, line: String) {
        lock(&self.shared.view).error(line);
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        self.stream.close(&self.shared, "the chip's run ended");
        if let Some(live) = LIVE.get()
            && Arc::ptr_eq(&live.shared, &self.shared)
        {
            live.busy.store(false, Ordering::Release);
        }
    }
}

/// After the bench: the view stays until the process is interrupted.
pub fn serve_on() {
    if LIVE.get().is_some() {
        eprintln!("xtask hil: the bench is done; the view serves until interrupted (Ctrl-C)");
        loop {
            std::thread::park();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hil::chip::ChipRecording;
    use embassy_time::Instant;
    use psmpa_core::record::{self, Header, RecordOut, Recorder};
    use psmpa_core::{FactSet, TraceEvent, TraceSink};
    use psmpa_fetch_tea::fetch_tea::FetchTea;

    /// The chip's log: each write of its recorder a `rec [..]` line.
    struct Lines(Vec<String>);

    impl RecordOut for Lines {
        fn write(&mut self, bytes: &[u8]) {
            let list: Vec<String> = bytes.iter().map(u8::to_string).collect();
            self.0.push(format!("rec [{}]", list.join(", ")));
        }
    }

    /// A board's recording of `events` (its start as `boards/rp/src/record.rs` writes it), as
    /// log lines.
    fn chip_lines(events: &[(u64, TraceEvent)]) -> Vec<String> {
        let mut out = Lines(Vec::new());
        let body: Vec<u8> = psmpa_fetch_tea::Settings::default()
            .to_record()
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .collect();
        let header = Header::new(1, psmpa_fetch_tea::fetch_tea::HASH);
        record::write_start(&mut out, &header, &body, psmpa_sim::replay::BOARD);
        let mut rec = Recorder::frames_only(out);
        for (ms, e) in events {
            TraceSink::<FetchTea>::record(&mut rec, Instant::from_millis(*ms), e);
        }
        rec.into_inner().0
    }

    fn shared() -> Arc<Shared> {
        let mission = fetch_tea_names().expect("the mission");
        Arc::new(Shared {
            view: Mutex::new(View::new(mission)),
            pace: None,
            source: "test".to_owned(),
        })
    }

    fn state(shared: &Shared) -> serde_json::Value {
        lock(&shared.view).update(0, 0, usize::MAX).0
    }

    fn facts(bits: u64) -> FactSet {
        FactSet::from_bits(bits)
    }

    #[test]
    fn the_chips_frames_reach_the_view_as_their_lines_arrive() {
        let events = [
            (
                5,
                TraceEvent::ModelEstablished {
                    beliefs: facts(0b11),
                },
            ),
            (
                9,
                TraceEvent::GoalReached {
                    beliefs: facts(0b101),
                },
            ),
        ];
        let lines = chip_lines(&events);
        let shared = shared();
        let mut chip = ChipRecording::shown(Claim::new(Arc::clone(&shared)));
        let mut seen = Vec::new();
        for line in &lines {
            chip.line(line).expect("a good line");
            seen.push(lock(&shared.view).events());
        }
        // One line a frame after the header's: each shown when its line came.
        assert_eq!(seen[seen.len() - 2..], [1, 2], "{seen:?}");
        let snap = lock(&shared.view).snapshot();
        assert_eq!(snap["time_ms"], 9);
        drop(chip);
        let state = state(&shared);
        assert_eq!(state["errors"], serde_json::json!([]), "{state}");
        assert!(
            state["ended"].to_string().contains("after 2 frames"),
            "{state}"
        );
    }

    #[test]
    fn a_cut_stream_and_a_bad_line_are_error_lines_and_the_view_goes_on() {
        let events = [
            (
                5,
                TraceEvent::ModelEstablished {
                    beliefs: facts(0b11),
                },
            ),
            (
                7,
                TraceEvent::GoalReached {
                    beliefs: facts(0b1),
                },
            ),
            (
                9,
                TraceEvent::GoalReached {
                    beliefs: facts(0b101),
                },
            ),
        ];
        let lines = chip_lines(&events);
        let shared = shared();
        let mut chip = ChipRecording::shown(Claim::new(Arc::clone(&shared)));
        let (last, whole) = lines.split_last().expect("lines");
        for line in whole {
            chip.line(line).expect("a good line");
        }
        // A line the chip's log garbled, then half of the last frame: the run ends there.
        assert!(chip.line("rec [1, 2, 999]").is_err());
        let half: Vec<&str> = last.trim_end_matches(']').split(", ").collect();
        let cut = format!("{}]", half[..half.len() / 2].join(", "));
        chip.line(&cut).expect("a frame's first half");
        drop(chip);
        let state = state(&shared);
        let errors = state["errors"].to_string();
        assert!(errors.contains("rec [1, 2, 999]"), "{errors}");
        assert!(errors.contains("cut"), "{errors}");
        assert_eq!(state["snapshot"]["events"], 2, "{state}");
        // The next run is shown from its header on, the error lines kept.
        let mut next = ChipRecording::shown(Claim::new(Arc::clone(&shared)));
        for line in &lines {
            next.line(line).expect("a good line");
        }
        drop(next);
        let state = super::tests::state(&shared);
        assert_eq!(state["snapshot"]["events"], 3, "{state}");
        assert!(state["errors"].to_string().contains("cut"), "{state}");
    }
}
