//! The checks of a mission file that host tools make before a robot runs it (feature `std`):
//! `psmpa-sim check`, and `include_mission!` when the robot is built. One implementation, so
//! that a file one accepts the other accepts, with the same one-line errors.
//!
//! * The file is strict JSON ([`json::strict`]: no duplicate key, no raw control character, ...).
//! * It loads ([`mission::load`]) at the largest capacities the core supports in a sensor set
//!   and a plan set (32 sensors, 32 plans; 64 actions, bodies of 16), every name resolved.
//! * Its goal is reachable ([`unreachable_goal`]).

use std::borrow::ToOwned;
use std::format;
use std::fs::{File, Metadata};
use std::io::Read as _;
use std::path::Path;
use std::string::{String, ToString};
use std::vec::Vec;

use crate::action::{ActuatorAction, SensorSet};
use crate::json;
use crate::mission::{self, AnyBehaviour, JsonError, LoadError, Problem, Tables};
use crate::planner::{Planner, PlanningError, Strategy};

/// The capacities a mission is checked at: 32 sensors, 64 actions, 32 plans of at most 16
/// actions; `NF` facts in fact sets of `W` words.
pub type Large<'a, const W: usize = 1, const NF: usize = 64> = Tables<'a, 32, 64, 32, 16, W, NF>;

/// A mission that failed to load, as one line naming the file and what is wrong. The bytes
/// were strict JSON ([`json::strict`]), so a syntax error from `serde-json-core` can only be a
/// number it cannot read as a whole number (`1e30`, `1.5`), the only values a mission holds
/// besides names.
pub fn error_line(file: &Path, e: &LoadError<'_>) -> String {
    let e = match e.problem {
        Problem::Json(JsonError::Syntax) => LoadError {
            problem: Problem::Json(JsonError::Number),
            ..*e
        },
        _ => *e,
    };
    // Names borrow from the file: keep any control character escaped.
    format!("{}: {}", file.display(), json::printable(&e.to_string()))
}

/// Why the task's goal can never hold, if it cannot: no sequence of actions reaches it from
/// the initial state even when every fact a sensor can perceive holds whenever it is needed
/// (perceivable facts are never deleted). That relaxation only helps the planner, so no plan
/// in it means no plan at all, whatever the sensors report.
pub fn unreachable_goal<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    m: &Tables<'_, NS, NA, NP, L, W, NF>,
) -> Option<String> {
    never_reached(m, m.task.goal).map(|expanded| {
        format!(
            "task.goal: no sequence of actions reaches {} from task.init, even with every percept holding ({expanded} states searched)",
            m.domain.names(m.task.goal)
        )
    })
}

/// How many states a search expanded to find that no sequence of actions makes every fact of
/// `facts` hold at once from the task's initial state, even when every fact a sensor can
/// perceive holds whenever it is needed (perceivable facts are never deleted); `None` when
/// some sequence does, or the search gave up (no verdict, no warning).
fn never_reached<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    m: &Tables<'_, NS, NA, NP, L, W, NF>,
    facts: crate::facts::FactSetOf<W>,
) -> Option<u32> {
    let d = &m.domain;
    let perceivable = d.perception_of(SensorSet::from_bits(u32::MAX));
    let relaxed: Vec<ActuatorAction<'_, W>> = d
        .actions()
        .iter()
        .map(|a| ActuatorAction {
            del: a.del.difference(perceivable),
            ..*a
        })
        .collect();
    let result = Planner::<4096, W>::new(Strategy::BreadthFirst).plan::<64>(
        &relaxed,
        m.task.init.union(perceivable),
        facts,
    );
    match result {
        Err(PlanningError::Unsolvable { expanded }) => Some(expanded),
        _ => None,
    }
}

/// A sensor timeout past which `warnings` asks whether it was meant: a minute, longer than a
/// robot should act on a reading it has not renewed.
pub const LONG_TIMEOUT_MS: u64 = 60_000;

/// What a mission file allows but is most likely a mistake, each as `field: why` (the file is
/// valid; the robot runs it as written):
///
/// * a plan body in an order its preconditions cannot run: an action needs a fact that only an
///   action later in the body adds, and that neither the plan's context nor a sensor gives,
///   nor the task's initial state (a fact it starts with that no action deletes);
/// * a plan context that can never hold: it needs a fact no action adds, no sensor perceives
///   and the task does not start with, or facts that each can hold but no sequence of actions
///   makes hold together (one action adds `at_door` and deletes `at_back_door`, another the
///   reverse);
/// * a sensor timeout longer than [`LONG_TIMEOUT_MS`]: a sensor that stops answering goes
///   unnoticed that long.
pub fn warnings<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    m: &Tables<'_, NS, NA, NP, L, W, NF>,
) -> Vec<String> {
    let d = &m.domain;
    let mut out = Vec::new();
    let perceivable = d.perception_of(SensorSet::from_bits(u32::MAX));
    let added = d
        .actions()
        .iter()
        .fold(crate::facts::FactSetOf::<W>::EMPTY, |a, x| a.union(x.add));
    let deleted = d
        .actions()
        .iter()
        .fold(crate::facts::FactSetOf::<W>::EMPTY, |a, x| a.union(x.del));
    // What the task starts with and nothing takes away holds whenever a plan runs.
    let always = m.task.init.difference(deleted);
    for (i, plan) in m.library.plans().iter().enumerate() {
        let given = plan.context.union(perceivable).union(always);
        for (k, id) in plan.body.iter().enumerate() {
            let Some(action) = d.action(*id) else {
                continue;
            };
            let earlier = plan.body.iter().take(k).filter_map(|a| d.action(*a));
            let before = earlier.fold(given, |a, x| a.union(x.add));
            let missing = action.pre.difference(before);
            let later = plan
                .body
                .iter()
                .skip(k.saturating_add(1))
                .filter_map(|a| d.action(*a))
                .find(|x| !missing.intersection(x.add).is_empty());
            if let Some(first) = later.map(|x| x.name) {
                let missing = missing.intersection(later.map_or(missing, |x| x.add));
                out.push(format!(
                    "plans[{i}].body: \"{}\" needs {}, which only \"{}\", later in the body, adds: the plan fails at its step {} unless something else makes it hold",
                    printable(action.name),
                    d.names(missing),
                    printable(first),
                    k.saturating_add(1)
                ));
            }
        }
        let never = plan
            .context
            .difference(added)
            .difference(perceivable)
            .difference(m.task.init);
        if !never.is_empty() {
            out.push(format!(
                "plans[{i}].context: {} can never hold (no action adds it, no sensor perceives it, the task does not start with it): the plan is never chosen",
                d.names(never)
            ));
        } else if plan.context.len() > 1
            && let Some(expanded) = never_reached(m, plan.context)
        {
            // Each fact can hold, but not all at once: an action that adds one deletes
            // another (`at_door` and `at_back_door`).
            out.push(format!(
                "plans[{i}].context: {} never hold together (no sequence of actions from task.init makes them all hold, even with every percept holding; {expanded} states searched): the plan is never chosen",
                d.names(plan.context)
            ));
        }
    }
    for (i, sensor) in d.sensors().iter().enumerate() {
        let ms = sensor.timeout.as_millis();
        if ms > LONG_TIMEOUT_MS {
            out.push(format!(
                "sensors[{i}].timeout_ms: {ms} ms: a sensor that stops answering goes unnoticed that long (more than {} s)",
                LONG_TIMEOUT_MS / 1000
            ));
        }
    }
    out
}

/// The largest input file a host tool reads: scenarios and missions are a few kilobytes, and a
/// file that never ends (`/dev/zero`) must not fill memory.
pub const MAX_INPUT: u64 = 1 << 20;

fn kind(meta: &Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
    }
    if meta.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Reads the input file at `path`, `what` it should be (`"scenario"`, `"mission"`): a regular
/// file of at most [`MAX_INPUT`] bytes. A FIFO, device or directory is refused before it is
/// opened (opening a FIFO waits for a writer forever; a device may never end).
pub fn read_input(path: &Path, what: &str) -> Result<Vec<u8>, String> {
    read_limited(path, what, MAX_INPUT)
}

/// [`read_input`] with a limit of `max` bytes (a recording may be larger than a scenario).
pub fn read_limited(path: &Path, what: &str, max: u64) -> Result<Vec<u8>, String> {
    let at = |message: String| format!("{}: {message}", path.display());
    let refuse = |meta: &Metadata| {
        at(format!(
            "is {}, not a {what} file: give the path of a file",
            kind(meta)
        ))
    };
    let meta = std::fs::metadata(path).map_err(|e| at(format!("cannot read the file: {e}")))?;
    if !meta.is_file() {
        return Err(refuse(&meta));
    }
    let file = File::open(path).map_err(|e| at(format!("cannot read the file: {e}")))?;
    // What was opened, in case the path changed since it was looked at.
    let meta = file
        .metadata()
        .map_err(|e| at(format!("cannot read the file: {e}")))?;
    if !meta.is_file() {
        return Err(refuse(&meta));
    }
    let too_large = || {
        at(format!(
            "the file is larger than {} MiB, the limit for a {what} file",
            max >> 20
        ))
    };
    if meta.len() > max {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    file.take(max.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| at(format!("cannot read the file: {e}")))?;
    if bytes.len() as u64 > max {
        return Err(too_large());
    }
    Ok(bytes)
}

/// Checks the mission file `file` (its `bytes`) for any platform and hands the mission to
/// `then`; one line naming the file and what is wrong otherwise.
pub fn check<R, const W: usize, const NF: usize>(
    file: &Path,
    bytes: &[u8],
    then: impl FnOnce(&Large<'_, W, NF>) -> R,
) -> Result<R, String> {
    let doc = json::strict_file(file, bytes)?;
    let loaded: mission::Loaded<'_, (), (), 32, 64, 32, 16, W, NF> =
        mission::load(&doc, &AnyBehaviour).map_err(|e| error_line(file, &e))?;
    let m = &loaded.mission;
    if let Some(why) = unreachable_goal(m) {
        return Err(format!("{}: {why}", file.display()));
    }
    as_the_macro_reads_it(file, &doc, m)?;
    Ok(then(m))
}

/// What `include_mission!` refuses in a mission that loads, for a host tool to refuse it too
/// (one verdict): `fact_descriptions` naming no fact or not an object ([`fact_descriptions`]),
/// and a name whose variant would be `ALL`, which would hide the generated `Fact::ALL`
/// (`Sensor::ALL`, ...). `doc` is the file's strict JSON.
pub fn as_the_macro_reads_it<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    file: &Path,
    doc: &[u8],
    m: &Tables<'_, NS, NA, NP, L, W, NF>,
) -> Result<(), String> {
    let value: serde_json::Value = serde_json::from_slice(doc).unwrap_or_default();
    fact_descriptions(&value).map_err(|e| format!("{}: {e}", file.display()))?;
    let d = &m.domain;
    let sensors: Vec<&str> = d.sensors().iter().map(|s| s.name).collect();
    let actions: Vec<&str> = d.actions().iter().map(|a| a.name).collect();
    let plans: Vec<&str> = m.library.plans().iter().map(|p| p.name).collect();
    for (table, one, names) in [
        ("facts", "Fact", d.fact_names()),
        ("events", "Event", d.event_names()),
        ("sensors", "Sensor", &sensors[..]),
        ("actions", "Action", &actions[..]),
        ("plans", "Plan", &plans[..]),
    ] {
        if let Some(name) = names.iter().find(|n| variant(n) == "ALL") {
            return Err(format!(
                "{}: {table} \"{}\" would be the variant ALL, which include_mission! gives the list of every one ({one}::ALL): rename it",
                file.display(),
                printable(name)
            ));
        }
    }
    Ok(())
}

/// Checks a mission's `fact_descriptions` (the file's JSON, `value`): absent, or an object
/// from a fact's name to its description; an entry that names no fact is an error (a typo
/// would lose it). `include_mission!` and `psmpa-sim check` give one verdict.
pub fn fact_descriptions(value: &serde_json::Value) -> Result<(), String> {
    let Some(described) = value.get("fact_descriptions") else {
        return Ok(());
    };
    let facts: Vec<&str> = value["facts"]
        .as_array()
        .map_or_else(Vec::new, |f| f.iter().filter_map(|n| n.as_str()).collect());
    let Some(map) = described.as_object() else {
        return Err(
            "fact_descriptions: an object from a fact's name to its description".to_owned(),
        );
    };
    if let Some(name) = map.keys().find(|k| !facts.contains(&k.as_str())) {
        return Err(format!(
            "fact_descriptions: `{}` is not a fact of the mission (not in `facts`)",
            printable(name)
        ));
    }
    Ok(())
}

/// The identifier `include_mission!` makes of a name: its words (split at `_` and at what
/// continues no identifier) each starting upper case (`go to door` is `GoToDoor`), `N` before
/// one that starts no identifier, `Unnamed` for none, `Self_` for `Self`.
pub fn variant(name: &str) -> String {
    let mut out = String::new();
    for word in name.split(|c: char| c == '_' || !unicode_ident::is_xid_continue(c)) {
        let mut chars = word.chars();
        if let Some(first) = chars.next() {
            // Upper case only where that is still one character that continues an identifier.
            let mut upper = first.to_uppercase();
            match (upper.next(), upper.next()) {
                (Some(u), None) if unicode_ident::is_xid_continue(u) => out.push(u),
                _ => out.push(first),
            }
            out.push_str(chars.as_str());
        }
    }
    if out.starts_with(|c: char| !unicode_ident::is_xid_start(c)) {
        out.insert(0, 'N');
    }
    match out.as_str() {
        "" => "Unnamed".to_owned(),
        "Self" => "Self_".to_owned(),
        _ => out,
    }
}

/// [`check`]'s errors keep the file's text printable: a name with a control character shows it
/// escaped (`json::printable`), as `psmpa-sim` prints every name.
pub fn printable(text: &str) -> String {
    json::printable(text).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = r#"{ "name": "hello", "facts": ["clear", "there"], "events": ["go"],
      "sensors": [{ "name": "bumper", "per": ["clear"], "mode": "cyclic", "period_ms": 20 }],
      "actions": [{ "name": "drive", "pre": ["clear"], "add": ["there"] }],
      "plans": [{ "name": "go there", "trigger": "go", "context": [], "body": ["drive"] }],
      "task": { "event": "go", "init": [], "goal": ["there"] } }"#;

    fn checked(text: &str) -> Result<usize, String> {
        check::<_, 1, 64>(Path::new("m.json"), text.as_bytes(), |m| {
            m.domain.actions().len()
        })
    }

    /// A fresh directory under the target's temporary space, removed by the test.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("psmpa-check-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn an_input_that_is_not_a_small_regular_file_is_refused_before_it_is_read() {
        let dir = scratch("inputs");
        // A FIFO with no writer: opening it would wait for ever, so it must not be opened.
        let fifo = dir.join("mission.json");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let (tx, rx) = std::sync::mpsc::channel();
            let f = fifo.clone();
            std::thread::spawn(move || tx.send(read_input(&f, "mission")));
            let e = rx
                .recv_timeout(std::time::Duration::from_secs(60))
                .expect("read_input on a FIFO returned within a minute")
                .unwrap_err();
            assert!(
                e.ends_with("is a FIFO, not a mission file: give the path of a file"),
                "{e}"
            );
        }
        // A device never ends.
        let e = read_input(Path::new("/dev/zero"), "mission").unwrap_err();
        assert_eq!(
            e,
            "/dev/zero: is a device, not a mission file: give the path of a file"
        );
        // One byte over the limit is refused; the limit itself is read.
        let big = dir.join("big.json");
        std::fs::write(&big, std::vec![b' '; MAX_INPUT as usize + 1]).unwrap();
        let e = read_input(&big, "mission").unwrap_err();
        assert!(
            e.ends_with("larger than 1 MiB, the limit for a mission file"),
            "{e}"
        );
        std::fs::write(&big, std::vec![b' '; MAX_INPUT as usize]).unwrap();
        assert_eq!(
            read_input(&big, "mission").unwrap().len(),
            MAX_INPUT as usize
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_body_check_counts_what_the_task_starts_with() {
        let m = r#"{ "name": "tool", "facts": ["tool", "made", "there"], "events": ["go"],
          "sensors": [],
          "actions": [{ "name": "use", "pre": ["tool"], "add": ["there"] },
                      { "name": "make", "pre": [], "add": ["tool", "made"] }],
          "plans": [{ "name": "p", "trigger": "go", "context": [], "body": ["use", "make"] }],
          "task": { "event": "go", "init": ["tool"], "goal": ["there", "made"] } }"#;
        let warned =
            |text: &str| check::<_, 1, 64>(Path::new("m.json"), text.as_bytes(), warnings).unwrap();
        // The task starts with the tool and nothing takes it: no warning.
        assert_eq!(warned(m), Vec::<String>::new());
        // Without it, the body's order is a likely mistake.
        let without = m.replace(r#""init": ["tool"]"#, r#""init": []"#);
        let w = warned(&without);
        assert!(w.len() == 1 && w[0].contains("later in the body"), "{w:?}");
        // An action that takes the tool away: it may be gone when the plan runs.
        let taken = m.replace(
            r#""add": ["there"] }"#,
            r#""add": ["there"], "del": ["tool"] }"#,
        );
        let w = warned(&taken);
        assert!(w.len() == 1 && w[0].contains("later in the body"), "{w:?}");
    }

    #[test]
    fn a_context_no_action_lets_hold_together_warns() {
        // Round 2 of the hostile rounds: "go" adds here and deletes there, "back" the reverse.
        let m = r#"{ "name": "two", "facts": ["here", "there", "done"], "events": ["e"],
          "sensors": [],
          "actions": [{ "name": "go", "pre": [], "add": ["here"], "del": ["there"] },
                      { "name": "back", "pre": [], "add": ["there"], "del": ["here"] },
                      { "name": "finish", "pre": ["here"], "add": ["done"] }],
          "plans": [{ "name": "p", "trigger": "e", "context": ["here", "there"], "body": ["finish"] }],
          "task": { "event": "e", "init": [], "goal": ["done"] } }"#;
        let warned =
            |text: &str| check::<_, 1, 64>(Path::new("m.json"), text.as_bytes(), warnings).unwrap();
        let w = warned(m);
        assert!(
            w.len() == 1 && w[0].starts_with("plans[0].context: {here, there} never hold together"),
            "{w:?}"
        );
        // An action that lets both hold: no warning.
        let both = m.replace(
            r#""add": ["there"], "del": ["here"]"#,
            r#""add": ["there"], "del": []"#,
        );
        assert_eq!(warned(&both), Vec::<String>::new());
        // The task starting with both: they hold together at first.
        let init = m.replace(r#""init": []"#, r#""init": ["here", "there"]"#);
        assert_eq!(warned(&init), Vec::<String>::new());
    }

    #[test]
    fn a_name_that_would_be_the_variant_all_is_refused() {
        for (from, to) in [
            (r#"["clear", "there"]"#, r#"["clear", "there", "ALL"]"#),
            (r#"["clear", "there"]"#, r#"["clear", "there", "a_l_l"]"#),
        ] {
            let e = checked(&OK.replace(from, to)).unwrap_err();
            assert!(
                e.starts_with("m.json: facts \"")
                    && e.contains("would be the variant ALL")
                    && e.contains("Fact::ALL"),
                "{e}"
            );
        }
        let e = checked(&OK.replace(r#""name": "bumper""#, r#""name": "A_LL""#)).unwrap_err();
        assert!(
            e.contains("sensors \"A_LL\"") && e.contains("Sensor::ALL"),
            "{e}"
        );
        // `all` is the variant `All`, and a name that only contains it another variant.
        assert!(checked(&OK.replace(r#""name": "bumper""#, r#""name": "all""#)).is_ok());
        assert!(
            checked(&OK.replace(
                r#"["clear", "there"]"#,
                r#"["clear", "there", "ALL_CLEAR"]"#
            ))
            .is_ok()
        );
    }

    #[test]
    fn fact_descriptions_are_checked_as_the_macro_checks_them() {
        let with = |d: &str| {
            OK.replace(
                r#""name": "hello","#,
                &format!(r#""name": "hello", "fact_descriptions": {d},"#),
            )
        };
        assert_eq!(checked(&with(r#"{"clear": "nothing ahead"}"#)), Ok(1));
        let e = checked(&with(r#"{"claer": "nothing ahead"}"#)).unwrap_err();
        assert_eq!(
            e,
            "m.json: fact_descriptions: `claer` is not a fact of the mission (not in `facts`)"
        );
        let e = checked(&with(r#"["clear"]"#)).unwrap_err();
        assert_eq!(
            e,
            "m.json: fact_descriptions: an object from a fact's name to its description"
        );
    }

    #[test]
    fn a_valid_mission_reaches_the_caller() {
        assert_eq!(checked(OK), Ok(1));
    }

    #[test]
    fn each_check_names_the_file_and_what_is_wrong() {
        let fly = OK.replace(r#""body": ["drive"]"#, r#""body": ["fly"]"#);
        let e = checked(&fly).unwrap_err();
        assert!(e.starts_with("m.json: plans[0].body"), "{e}");
        assert!(e.contains("fly"), "{e}");
        let twice = OK.replace(
            r#""name": "hello","#,
            r#""name": "hello", "name": "again","#,
        );
        assert!(checked(&twice).unwrap_err().contains("appears twice"));
        let unreachable = OK.replace(r#""add": ["there"]"#, r#""add": []"#);
        assert!(checked(&unreachable).unwrap_err().contains("task.goal"));
        let number = OK.replace("\"period_ms\": 20", "\"period_ms\": 2.5");
        assert!(checked(&number).unwrap_err().contains("whole number"));
    }
}
