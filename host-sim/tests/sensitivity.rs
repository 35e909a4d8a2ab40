//! `psmpa-sim sensitivity`: the grid, its intervals, determinism, properties that follow from
//! how the world is built, bad input and the plot.

mod common;

use common::{assert_refused, assert_success, bin, folder};
use serde_json::Value;

const FRACTIONS: [u64; 9] = [10, 20, 30, 40, 50, 60, 70, 80, 90];
const CYCLES: [u64; 6] = [500, 1_000, 2_000, 3_000, 4_000, 6_000];

/// Few worlds: tests run the debug build.
const RUNS: &str = "12";

fn study(args: &[&str], threads: Option<&str>) -> (Value, String) {
    let mut cmd = bin();
    cmd.arg("sensitivity").args(args);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t);
    }
    let out = cmd.output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    let json = if args.contains(&"--json") {
        serde_json::from_str(&text).unwrap()
    } else {
        Value::Null
    };
    (json, text)
}

/// `{mean, lo, hi, n}` with lo <= mean <= hi, within `[0, max]`; its `n`.
fn interval(v: &Value, max: f64, what: &str) -> u64 {
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{what}.{k}: {v}"));
    let (mean, lo, hi) = (f("mean"), f("lo"), f("hi"));
    assert!(
        0.0 <= lo && lo <= mean && mean <= hi && hi <= max,
        "{what}: {v}"
    );
    v["n"].as_u64().unwrap()
}

fn cell(pass: &Value, fraction: u64, cycle: u64) -> &Value {
    pass["cells"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["sense_fraction_pct"] == fraction && c["cycle_ms"] == cycle)
        .unwrap_or_else(|| panic!("no cell {fraction} % {cycle} ms"))
}

#[test]
fn json_has_every_cell_with_ordered_intervals() {
    let (j, _) = study(&["--runs", RUNS, "--seed", "3", "--json"], None);
    let runs: u64 = RUNS.parse().unwrap();
    assert_eq!(j["runs"], runs);
    assert_eq!(j["seed"], 3);
    assert_eq!(
        j["settings"]["sense_fraction_pct"],
        serde_json::json!(FRACTIONS)
    );
    assert_eq!(j["settings"]["cycle_ms"], serde_json::json!(CYCLES));
    for name in ["clean", "faults"] {
        let pass = &j[name];
        assert_eq!(pass["name"], name);
        // P-SMPA's figures come out of the runs: one run a world.
        let p = &pass["psmpa"];
        assert_eq!(interval(&p["collisions"], f64::INFINITY, "psmpa"), runs);
        let n = interval(&p["detection_rate"], 1.0, "psmpa");
        assert!(0 < n && n <= runs, "{p}");
        assert_eq!(pass["cells"].as_array().unwrap().len(), 54);
        for f in FRACTIONS {
            for c in CYCLES {
                let cell = cell(pass, f, c);
                assert_eq!(cell["sense_ms"].as_u64().unwrap(), c * f / 100);
                assert_eq!(
                    cell["sense_ms"].as_u64().unwrap() + cell["act_ms"].as_u64().unwrap(),
                    c
                );
                let s = &cell["smpa"];
                let what = format!("{name} {f} % {c} ms");
                assert_eq!(interval(&s["collisions"], f64::INFINITY, &what), runs);
                // Detection is over the same obstacles as P-SMPA's: the same runs count.
                assert_eq!(interval(&s["detection_rate"], 1.0, &what), n);
                if !s["met_detection_rate"].is_null() {
                    assert!(interval(&s["met_detection_rate"], 1.0, &what) <= n);
                }
                let reached = runs - s["not_reached"].as_u64().unwrap();
                assert!(interval(&cell["time_ratio"], f64::INFINITY, &what) <= reached);
            }
        }
    }
    let harder = &j["harder"];
    assert_eq!(harder["bumper_min_contact"], "one bumper period");
    let rows = harder["rows"].as_array().unwrap();
    let speeds: Vec<f64> = rows
        .iter()
        .map(|r| r["person_speed_mps"].as_f64().unwrap())
        .collect();
    assert_eq!(speeds, [0.0, 0.5, 1.0, 1.5, 3.0]);
    for r in rows {
        for arch in ["psmpa", "smpa"] {
            let what = format!("harder {arch} {}", r["person_speed_mps"]);
            assert_eq!(interval(&r[arch]["collisions"], f64::INFINITY, &what), runs);
            if !r[arch]["detection_rate"].is_null() {
                assert!(interval(&r[arch]["detection_rate"], 1.0, &what) <= runs);
            }
        }
    }
}

/// In the harder world with nobody walking, P-SMPA still detects every obstacle a delivered
/// sample was certain to register (its sensors run for the whole walk and a standing box
/// cannot come closer between samples), but a ball it touched for less than one bumper period
/// before it was taken away is a collision the bumper could not feel. Walking people can reach
/// it between two samples: its collisions are counted, not assumed to be 0.
#[test]
fn the_harder_world_measures_what_psmpa_misses() {
    let (j, _) = study(&["--runs", "30", "--seed", "8", "--json"], None);
    let rows = j["harder"]["rows"].as_array().unwrap();
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap();
    assert_eq!(f(&rows[0]["psmpa"]["detection_rate"], "mean"), 1.0);
    let still = f(&rows[0]["psmpa"]["collisions"], "mean");
    let running = f(&rows[4]["psmpa"]["collisions"], "mean");
    assert!(running > still, "{running} against {still}");
    assert!(f(&rows[4]["psmpa"]["detection_rate"], "mean") < 1.0);
    let (_, text) = study(&["--runs", "2"], None);
    assert!(text.contains("== the harder world"), "{text}");
}

#[test]
fn the_same_seed_gives_the_same_json_on_any_number_of_threads() {
    let args = ["--runs", "6", "--seed", "11", "--json"];
    let (_, one) = study(&args, Some("1"));
    let (_, two) = study(&args, Some("2"));
    let (_, three) = study(&args, Some("3"));
    assert_eq!(one, two);
    assert_eq!(one, three);
    let (_, other) = study(&["--runs", "6", "--seed", "12", "--json"], Some("2"));
    assert_ne!(one, other, "the seed draws the worlds");
}

/// Properties that follow from how SMPA is built, whatever the worlds drawn:
/// - At 90 % sense and a 0.5 s cycle the robot walks 50 ms (at most 10 mm) between sense
///   phases of 450 ms, in which the sonar samples at least twice: no box crosses the sonar's
///   0.25 m detection zone unseen. At 10 % and 6 s it walks 5.4 s blind (0.27 m or more)
///   between 0.6 s of sensing. So of the obstacles it meets, it detects more at the former.
/// - It walks only a tenth of the time at 90 % sense, nine tenths at 10 %: at any cycle
///   length the time ratio is larger at 90 %.
/// - P-SMPA's sensors run for the whole walk, and "detectable" is measured on its run: it
///   detects at least as much as SMPA in every cell.
#[test]
fn smpa_settings_move_the_figures_the_way_the_world_says() {
    let (j, _) = study(&["--runs", "20", "--seed", "5", "--json"], None);
    let pass = &j["clean"];
    let f = |v: &Value, k: &str| v[k].as_f64().unwrap();
    let good = &cell(pass, 90, 500)["smpa"]["met_detection_rate"];
    let bad = &cell(pass, 10, 6_000)["smpa"]["met_detection_rate"];
    assert!(f(good, "lo") > f(bad, "hi"), "{good} against {bad}");
    for c in CYCLES {
        let slow = &cell(pass, 90, c)["time_ratio"];
        let fast = &cell(pass, 10, c)["time_ratio"];
        assert!(
            f(slow, "lo") > f(fast, "hi"),
            "{c} ms: {slow} against {fast}"
        );
        assert!(f(fast, "mean") >= 1.0, "{c} ms: {fast}");
    }
    let p = f(&pass["psmpa"]["detection_rate"], "hi");
    for cell in pass["cells"].as_array().unwrap() {
        assert!(f(&cell["smpa"]["detection_rate"], "mean") <= p, "{cell}");
    }
}

#[test]
fn text_names_the_closest_setting() {
    let (_, text) = study(&["--runs", "4"], None);
    assert!(
        text.contains("SMPA comes closest to P-SMPA at sense "),
        "{text}"
    );
    assert!(text.contains("cycle 0.5 s"), "{text}");
    assert!(text.contains("with sensor faults and latencies"), "{text}");
    assert!(text.contains("P-SMPA: detection rate "), "{text}");
}

#[test]
fn bad_input_is_refused() {
    for runs in ["0", "100001", "-3", "many"] {
        let out = bin()
            .args(["sensitivity", &format!("--runs={runs}")])
            .output()
            .unwrap();
        assert_refused(&out, &["--runs"]);
    }
    let out = bin()
        .args([
            "sensitivity",
            "--runs",
            "1",
            "--plot",
            "/nonexistent-dir/s.svg",
        ])
        .output()
        .unwrap();
    assert_refused(&out, &["/nonexistent-dir/s.svg"]);
    let dir = folder("sensitivity-plot-dir");
    let out = bin()
        .args(["sensitivity", "--runs", "1", "--plot"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_refused(&out, &[dir.to_str().unwrap()]);
}

#[test]
fn plot_writes_an_svg_with_its_legend() {
    let dir = folder("sensitivity-plot");
    let path = dir.join("s.svg");
    let out = bin()
        .args(["sensitivity", "--runs", "3", "--json", "--plot"])
        .arg(&path)
        .output()
        .unwrap();
    assert_success(&out);
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        stderr.trim_end(),
        format!("psmpa-sim: wrote {}", path.display())
    );
    let svg = std::fs::read_to_string(&path).unwrap();
    assert!(svg.starts_with("<svg"), "{}", &svg[..svg.len().min(200)]);
    for label in [
        "cycle 0.5 s",
        "cycle 1 s",
        "cycle 2 s",
        "cycle 3 s",
        "cycle 4 s",
        "cycle 6 s",
        "P-SMPA (",
        "paper (NAO; sense fraction assumed 50 %)",
        "detection rate (%)",
        "SMPA sense fraction",
    ] {
        assert!(svg.contains(label), "{label} missing");
    }
    assert_eq!(names_of(&dir), ["s.svg"], "no temporary file left");
}

fn names_of(dir: &std::path::Path) -> Vec<String> {
    common::names_in(dir)
}

/// Common random numbers: a world and its faulty twin differ only in the faults, and a clean
/// world has none; every interference falls within the unhindered walk.
#[test]
fn a_clean_world_and_its_faulty_twin_differ_only_in_the_faults() {
    use psmpa_sim::cli::sensitivity::{with_phases, world};
    let mut faulty = 0;
    for i in 0..200 {
        let (clean, faults) = (world(9, i, false), world(9, i, true));
        assert_eq!(clean.interferences, faults.interferences);
        assert_eq!(
            (clean.door_um, clean.speed_um_per_ms, clean.avoid_ms),
            (faults.door_um, faults.speed_um_per_ms, faults.avoid_ms)
        );
        assert_eq!(
            (clean.sonar.period_ms, clean.bumper_period_ms),
            (faults.sonar.period_ms, faults.bumper_period_ms)
        );
        assert_eq!(clean.seed, faults.seed, "the same noise stream");
        assert_eq!(
            (
                clean.sonar.noise_um,
                clean.sonar.dropout,
                clean.sonar.latency_ms
            ),
            (0, 0, 0)
        );
        assert_eq!(clean.bumper_latency_ms, 0);
        faulty += u32::from(
            faults.sonar.noise_um > 0 || faults.sonar.dropout > 0 || faults.sonar.latency_ms > 0,
        );
        assert!(!clean.interferences.is_empty());
        let walk_ms = (clean.door_um / clean.speed_um_per_ms) as u32;
        assert!(clean.interferences.iter().all(|x| x.at_ms <= walk_ms));
        let cell = with_phases(&clean, 30, 2_000);
        assert_eq!((cell.sense_ms, cell.act_ms), (600, 1_400));
        assert_eq!(cell.interferences, clean.interferences);
    }
    assert!(faulty > 150, "faults drawn in most worlds: {faulty} of 200");
}

/// One run shows no spread: its means come without an interval (`lo` and `hi` null, `[1 run]`
/// in the text), never a zero-width 95 % interval.
#[test]
fn one_run_gives_means_without_an_interval() {
    fn walk(v: &Value, found: &mut usize) {
        match v {
            Value::Object(o) => {
                if o.get("n").and_then(Value::as_u64) == Some(1) {
                    assert!(o["lo"].is_null() && o["hi"].is_null(), "{v}");
                    assert!(o["mean"].is_f64(), "{v}");
                    *found += 1;
                }
                o.values().for_each(|x| walk(x, found));
            }
            Value::Array(a) => a.iter().for_each(|x| walk(x, found)),
            _ => {}
        }
    }
    let (j, _) = study(&["--runs", "1", "--seed", "3", "--json"], None);
    let mut found = 0;
    walk(&j, &mut found);
    assert!(found > 0, "{j}");
    let (_, text) = study(&["--runs", "1", "--seed", "3"], None);
    assert!(text.contains("[1 run]"), "{text}");
    // With two runs, intervals again.
    let (j, _) = study(&["--runs", "2", "--seed", "3", "--json"], None);
    let mut found = 0;
    walk(&j, &mut found);
    let text = j.to_string();
    assert!(
        text.contains("\"lo\":0") || text.contains("\"lo\":1"),
        "{text}"
    );
}
