//! `cargo xtask view-soak`: psmpa-sim's live view under load, measured. The release binary runs
//! `view scenarios/sonar-8.json --speed 100 --repeat N` (sonar-8 again and again, virtual time
//! going on) for the minutes asked, with pages following its Server-Sent Events as a browser
//! tab does. Each second it reads the server's resident memory (`/proc/PID/status`) and
//! `/snapshot`; the pages note how late the simulator's latest event came (`late_ms`).
//!
//! It fails when the view does not keep up (virtual time under 95 % of 100 times the wall
//! time), when its lag grows (the second half's latest event later than the first half's by
//! more than [`MAX_GROWTH_MS`]: a shared machine's load makes events late for a while, a view
//! that cannot keep up makes them later and later), or when memory grows (the second half's
//! most above the first half's by more than a fifth and a MiB). Then it writes the figures
//! into docs/simulator.md, between the `view-soak` markers.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::firmware;

/// The speed the view must keep up with, times real time.
const SPEED: f64 = 100.0;
/// How much later the second half's latest event may come than the first half's, ms.
const MAX_GROWTH_MS: u64 = 250;

/// What the pages saw.
#[derive(Default)]
struct Seen {
    /// Updates received, all pages.
    updates: u64,
    /// Updates whose samples were thinned.
    coalesced: u64,
    /// The latest event's lateness, most since the last minute's row.
    late_ms: u64,
    /// The most over the whole run.
    late_max_ms: u64,
    /// A page's stream ended or failed: why.
    broken: Option<String>,
}

/// One minute's row.
struct Row {
    minute: u64,
    events: u64,
    virtual_s: f64,
    late_ms: u64,
    rss_kib: u64,
    updates: u64,
}

/// Stops the server when dropped.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `GET path` on `host`: the body, or why not.
fn get(host: &str, path: &str) -> Result<String, String> {
    let mut s = TcpStream::connect(host).map_err(|e| format!("{host}: {e}"))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .map_err(|e| e.to_string())?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: {host}\r\n\r\n").map_err(|e| e.to_string())?;
    let mut text = String::new();
    s.read_to_string(&mut text)
        .map_err(|e| format!("GET {path}: {e}"))?;
    let (head, body) = text
        .split_once("\r\n\r\n")
        .ok_or_else(|| format!("GET {path}: no response"))?;
    if !head.starts_with("HTTP/1.0 200") && !head.starts_with("HTTP/1.1 200") {
        return Err(format!(
            "GET {path}: {}",
            head.lines().next().unwrap_or_default()
        ));
    }
    Ok(body.to_owned())
}

/// A page: loads `/`, then follows `/events` until `stop`, noting what it sees.
fn page(host: String, stop: Arc<AtomicBool>, seen: Arc<Mutex<Seen>>) {
    let follow = || -> Result<(), String> {
        get(&host, "/")?;
        let mut s = TcpStream::connect(&host).map_err(|e| e.to_string())?;
        s.set_read_timeout(Some(Duration::from_secs(1)))
            .map_err(|e| e.to_string())?;
        // HTTP/1.0: the stream is not chunked, one `data:` line an update.
        write!(
            s,
            "GET /events HTTP/1.0\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n"
        )
        .map_err(|e| e.to_string())?;
        let mut lines = BufReader::new(s);
        let mut line = String::new();
        while !stop.load(Ordering::Relaxed) {
            line.clear();
            match lines.read_line(&mut line) {
                Ok(0) => return Err("the server closed the page's stream".to_owned()),
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    continue;
                }
                Err(e) => return Err(e.to_string()),
            }
            let Some(data) = line.strip_prefix("data: ") else {
                continue;
            };
            let update: Value = serde_json::from_str(data).map_err(|e| e.to_string())?;
            let late = update["status"]["late_ms"].as_u64().unwrap_or(0);
            let mut seen = seen.lock().map_err(|e| e.to_string())?;
            seen.updates += 1;
            seen.coalesced += u64::from(update["coalesced"] == true);
            seen.late_ms = seen.late_ms.max(late);
            seen.late_max_ms = seen.late_max_ms.max(late);
        }
        Ok(())
    };
    if let Err(e) = follow()
        && let Ok(mut seen) = seen.lock()
    {
        seen.broken.get_or_insert(e);
    }
}

/// The resident memory of process `pid`, KiB.
fn rss_kib(pid: u32) -> Result<u64, String> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .map_err(|e| format!("the server's /proc status: {e}"))?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .ok_or_else(|| "no VmRSS in the server's /proc status".to_owned())
}

/// Runs the soak for `minutes` with `pages` pages following; writes the figures when it passes.
pub fn run(minutes: u64, pages: usize) -> Result<(), String> {
    let root = firmware::root();
    let doc = root.join("docs/simulator.md");
    // The markers first: not ten minutes measured for a page that cannot take them.
    crate::pages::check_pages(&[(doc.clone(), "view-soak")])?;
    let sim = firmware::build_host_sim()?;
    let scenario = root.join("scenarios/sonar-8.json");
    let mut child = Command::new(&sim)
        .arg("view")
        .arg(&scenario)
        .args(["--speed", "100", "--repeat", "1000000", "--port", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("{}: {e}", sim.display()))?;
    let pid = child.id();
    let stdout = child.stdout.take().ok_or("no stdout from psmpa-sim")?;
    let server = Server(child);
    let mut first = String::new();
    BufReader::new(stdout)
        .read_line(&mut first)
        .map_err(|e| format!("psmpa-sim view: {e}"))?;
    let host = first
        .trim()
        .strip_prefix("psmpa-sim view: http://")
        .map(|h| h.trim_end_matches('/').to_owned())
        .ok_or_else(|| format!("psmpa-sim view printed no address: {first:?}"))?;
    eprintln!(
        "xtask view-soak: sonar-8 at {SPEED}x on http://{host}/ for {minutes} min, {pages} pages following"
    );
    let stop = Arc::new(AtomicBool::new(false));
    let seen = Arc::new(Mutex::new(Seen::default()));
    let followers: Vec<_> = (0..pages)
        .map(|_| {
            let (host, stop, seen) = (host.clone(), Arc::clone(&stop), Arc::clone(&seen));
            std::thread::spawn(move || page(host, stop, seen))
        })
        .collect();
    let started = Instant::now();
    let mut rows = Vec::new();
    let mut samples = Vec::new();
    let mut last_updates = 0;
    let measured = (|| -> Result<(), String> {
        for second in 1..=minutes * 60 {
            let due = started + Duration::from_secs(second);
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            let rss = rss_kib(pid)?;
            samples.push(rss);
            let snap: Value = serde_json::from_str(&get(&host, "/snapshot")?)
                .map_err(|e| format!("/snapshot: {e}"))?;
            if second % 60 == 0 {
                let mut seen = seen.lock().map_err(|e| e.to_string())?;
                if let Some(e) = &seen.broken {
                    return Err(format!("a page: {e}"));
                }
                let row = Row {
                    minute: second / 60,
                    events: snap["events"].as_u64().unwrap_or(0),
                    virtual_s: snap["time_ms"].as_u64().unwrap_or(0) as f64 / 1000.0,
                    late_ms: seen.late_ms,
                    rss_kib: rss,
                    updates: seen.updates - last_updates,
                };
                last_updates = seen.updates;
                seen.late_ms = 0;
                eprintln!(
                    "  minute {:>2}: {} events, virtual time {:.0} s ({:.1}x), latest event at most {} ms late, RSS {:.1} MiB, {} updates to the pages",
                    row.minute,
                    row.events,
                    row.virtual_s,
                    row.virtual_s / started.elapsed().as_secs_f64(),
                    row.late_ms,
                    row.rss_kib as f64 / 1024.0,
                    row.updates
                );
                rows.push(row);
            }
        }
        Ok(())
    })();
    stop.store(true, Ordering::Relaxed);
    for f in followers {
        let _ = f.join();
    }
    drop(server);
    measured?;
    let wall_s = started.elapsed().as_secs_f64();
    let seen = seen.lock().map_err(|e| e.to_string())?;
    let last = rows.last().ok_or("the soak ran less than a minute")?;
    let speed = last.virtual_s / wall_s;
    let half = samples.len() / 2;
    let first_half = samples[..half].iter().copied().max().unwrap_or(0);
    let second_half = samples[half..].iter().copied().max().unwrap_or(0);
    let mut failed = Vec::new();
    if speed < 0.95 * SPEED {
        failed.push(format!(
            "the view fell behind: virtual time ran at {speed:.1}x real time, not {SPEED}x"
        ));
    }
    let (early, late) = rows.split_at(rows.len() / 2);
    let worst = |rows: &[Row]| rows.iter().map(|r| r.late_ms).max().unwrap_or(0);
    if worst(late) > worst(early) + MAX_GROWTH_MS {
        failed.push(format!(
            "the lag grew: an event came {} ms late in the second half, at most {} in the first",
            worst(late),
            worst(early)
        ));
    }
    if second_half as f64 > first_half as f64 * 1.2 + 1024.0 {
        failed.push(format!(
            "memory grew: RSS at most {:.1} MiB in the first half, {:.1} MiB in the second",
            first_half as f64 / 1024.0,
            second_half as f64 / 1024.0
        ));
    }
    if !failed.is_empty() {
        return Err(failed.join("; "));
    }
    let mib = |k: u64| format!("{:.1}", k as f64 / 1024.0);
    let plural = if minutes == 1 { "" } else { "s" };
    let mut text = format!(
        "\nMeasured by `cargo xtask view-soak` ({minutes} minute{plural}, {pages} pages following): \
         `psmpa-sim view scenarios/sonar-8.json --speed 100 --repeat 1000000` ran {} events, \
         {:.0} s of virtual time in {:.0} s ({speed:.1}x real time); the latest event came at \
         most {} ms late; {} of the pages' {} updates were coalesced; the server's resident \
         memory stayed from {} to {} MiB.\n\n\
         | minute | events | virtual time, s | latest event late, ms | RSS, MiB |\n\
         |---|---|---|---|---|\n",
        crate::hil::thousands(last.events),
        last.virtual_s,
        wall_s,
        seen.late_max_ms,
        crate::hil::thousands(seen.coalesced),
        crate::hil::thousands(seen.updates),
        mib(samples.iter().copied().min().unwrap_or(0)),
        mib(samples.iter().copied().max().unwrap_or(0)),
    );
    for r in &rows {
        text.push_str(&format!(
            "| {} | {} | {:.0} | {} | {} |\n",
            r.minute,
            crate::hil::thousands(r.events),
            r.virtual_s,
            r.late_ms,
            mib(r.rss_kib)
        ));
    }
    crate::pages::write_between(&doc, "view-soak", &text)?;
    println!("{text}");
    println!("the figures written into docs/simulator.md");
    Ok(())
}
