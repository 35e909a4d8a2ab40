//! The chip's own flight recording, read while the run goes on: the `rec [bytes]` lines of its
//! defmt log (`boards/rp/src/record.rs`), decoded frame by frame as they come off RTT, as a
//! debug probe would read them. What the robot sampled and read, and when it switched a
//! sensor on or off, is judged from these frames and from the pins, never from memory the
//! firmware keeps for a debugger.

use psmpa_core::record::{self, Frame, HEADER_LEN, Header};

/// The streamed recording of one run, as far as it has come.
#[derive(Default)]
pub struct ChipRecording {
    bytes: Vec<u8>,
    /// Where the next frame starts, once the header and prologue are whole.
    next: Option<usize>,
    /// The header's tick rate.
    tick_hz: u64,
    /// A second header came (the ring sent after a watchdog reset): the stream ended.
    ended: bool,
    /// The live view showing this run (`cargo xtask hil --view`), once claimed.
    live: Option<crate::live::Claim>,
}

impl ChipRecording {
    /// A run shown on the live view by `claim`.
    #[cfg(test)]
    pub fn shown(claim: crate::live::Claim) -> Self {
        Self {
            live: Some(claim),
            ..Self::default()
        }
    }

    /// Takes one decoded log line; the frames it completes, each with its instant in ns since
    /// the chip booted. Lines that are not the recording's are ignored.
    pub fn line(&mut self, text: &str) -> Result<Vec<(u64, Frame<1>)>, String> {
        if self.ended {
            return Ok(Vec::new());
        }
        let Some(bytes) = psmpa_sim::replay::rec_bytes(text) else {
            return Ok(Vec::new());
        };
        let bytes = match bytes {
            Ok(b) => b,
            Err(e) => {
                if let Some(live) = &self.live {
                    live.error(format!("the chip's recording: {e}"));
                }
                return Err(e);
            }
        };
        if bytes.starts_with(&record::MAGIC) && !self.bytes.is_empty() {
            // What the ring kept, sent again after a reset: not new events.
            self.ended = true;
            return Ok(Vec::new());
        }
        if self.bytes.is_empty() && self.live.is_none() {
            // The view follows a run from its header on.
            self.live = crate::live::claim();
        }
        if let Some(live) = &mut self.live {
            live.bytes(&bytes);
        }
        self.bytes.extend_from_slice(&bytes);
        self.frames()
    }

    fn frames(&mut self) -> Result<Vec<(u64, Frame<1>)>, String> {
        let mut out = Vec::new();
        let Some(mut at) = self.next.or_else(|| self.prologue_end()) else {
            return Ok(out);
        };
        if self.tick_hz == 0 {
            let header = Header::decode(&self.bytes).map_err(|e| format!("its header: {e}"))?;
            self.tick_hz = u64::from(header.tick_hz);
        }
        while at < self.bytes.len() {
            match Frame::<1>::decode(&self.bytes[at..], at) {
                Ok((frame, used)) => {
                    let ns = u128::from(frame.ticks) * 1_000_000_000 / u128::from(self.tick_hz);
                    out.push((u64::try_from(ns).unwrap_or(u64::MAX), frame));
                    at += used;
                }
                Err(record::RecordError::Cut { .. }) => break,
                Err(e) => return Err(e.to_string()),
            }
        }
        self.next = Some(at);
        Ok(out)
    }

    /// Where the frames begin: after the header, the prologue's length, its bytes, its kind
    /// byte and its CRC-32; `None` until all of that has come.
    fn prologue_end(&self) -> Option<usize> {
        let len = self.bytes.get(HEADER_LEN..HEADER_LEN + 4)?;
        let len = u32::from_le_bytes([len[0], len[1], len[2], len[3]]) as usize;
        let end = HEADER_LEN + 4 + len + 1 + 4;
        (self.bytes.len() >= end).then_some(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_time::Instant;
    use psmpa_core::record::{RecordOut, Recorder};
    use psmpa_core::{SensorId, TraceEvent, TraceSink};

    struct Lines(Vec<String>);

    impl RecordOut for Lines {
        fn write(&mut self, bytes: &[u8]) {
            let list: Vec<String> = bytes.iter().map(u8::to_string).collect();
            self.0.push(format!("rec [{}]", list.join(", ")));
        }
    }

    #[test]
    fn frames_come_out_as_their_lines_arrive_with_their_instants() {
        let sonar = SensorId::new(0).unwrap();
        let mut out = Lines(Vec::new());
        record::write_start(
            &mut out,
            &Header {
                tick_hz: 1_000_000,
                ..Header::new(1, 7)
            },
            b"prologue",
            2,
        );
        let mut rec = Recorder::frames_only(out);
        for (us, on) in [(10, true), (2_000, false)] {
            let e = if on {
                TraceEvent::SensorOn { sensor: sonar }
            } else {
                TraceEvent::SensorOff { sensor: sonar }
            };
            TraceSink::<psmpa_fetch_tea::fetch_tea::FetchTea>::record(
                &mut rec,
                Instant::from_micros(us),
                &e,
            );
        }
        let lines = rec.into_inner().0;
        let mut chip = ChipRecording::default();
        let mut got = Vec::new();
        for line in &lines {
            got.extend(chip.line(&format!("INFO {line}")).unwrap());
            got.extend(chip.line("INFO go to door started").unwrap());
        }
        let seen: Vec<_> = got.iter().map(|(ns, f)| (*ns, f.power())).collect();
        // A frame's ticks are the host's here, read as a 1 MHz chip's: µs.
        let us = |t: u64| Instant::from_micros(t).as_ticks() * 1_000;
        assert_eq!(
            seen,
            [
                (us(10), Some((sonar, true))),
                (us(2_000), Some((sonar, false)))
            ]
        );
        // The ring's recording after a reset is not read as new events.
        assert!(chip.line(&lines[0]).unwrap().is_empty());
        assert!(chip.line(&lines[lines.len() - 1]).unwrap().is_empty());
    }
}
