//! Loading scenario files on the host, with errors that name the file and the field or the
//! line and column.
//!
//! A file must first be strict JSON ([`json::strict`], which also decodes `\u` escapes). The
//! scenario is then parsed by `serde-json-core`, the parser the firmware uses. That parser
//! reports no position and drops serde's messages (its message-keeping feature can panic), so
//! when it rejects a file the same file is read once more with `serde_json` and
//! `serde_path_to_error`, only to say where and what.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::json;
use crate::scenario::{Scenario, ScenarioError, ScenarioFile};

/// A scenario file that could not be used.
#[derive(Debug)]
pub struct LoadError {
    /// The file.
    pub file: PathBuf,
    /// What is wrong, in one line.
    pub message: String,
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.file.display(), self.message)
    }
}

impl std::error::Error for LoadError {}

/// Reads and validates a scenario file.
pub fn load(path: &Path) -> Result<Scenario, LoadError> {
    let bytes = std::fs::read(path).map_err(|e| LoadError {
        file: path.to_path_buf(),
        message: format!("cannot read the file: {e}"),
    })?;
    parse(path, &bytes)
}

/// Validates scenario bytes that came from `file`.
pub fn parse(file: &Path, bytes: &[u8]) -> Result<Scenario, LoadError> {
    let fail = |message: String| LoadError {
        file: file.to_path_buf(),
        // Names and keys from the file may hold control characters: never print them raw.
        message: json::printable(&message).into_owned(),
    };
    if let Some(message) = not_an_object(bytes) {
        return Err(fail(message.into()));
    }
    let doc = json::strict(bytes).map_err(|e| fail(e.to_string()))?;
    Scenario::parse(&doc).map_err(|e| {
        fail(match e {
            // The original bytes: serde_json decodes escapes itself, and columns stay true.
            ScenarioError::Json(inner) => diagnose(bytes).unwrap_or_else(|| inner.to_string()),
            invalid @ ScenarioError::Invalid { .. } => invalid.to_string(),
        })
    })
}

/// A file that is empty or starts with something other than an object. Checked before the
/// JSON itself: a scenario is an object whatever else the file holds (even 10⁶ `[`).
fn not_an_object(bytes: &[u8]) -> Option<&'static str> {
    match bytes.iter().find(|b| !b.is_ascii_whitespace()) {
        None => Some("the file is empty: a scenario is a JSON object `{ ... }`"),
        // Not ASCII: a byte order mark or bad UTF-8, which `json::strict` names.
        Some(&b) if b != b'{' && b.is_ascii() => {
            Some("the top level: expected a JSON object `{ ... }`")
        }
        Some(_) => None,
    }
}

/// Where and why a file that `serde-json-core` rejected is wrong, according to `serde_json`.
fn diagnose(bytes: &[u8]) -> Option<String> {
    // serde_json takes an array for a struct (fields by position), serde-json-core does not.
    let value = serde_json::from_slice::<serde_json::Value>(bytes).ok();
    if let Some(path) = value.as_ref().and_then(array_for_object) {
        return Some(format!("{path}: invalid type: array, expected an object"));
    }
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let result: Result<ScenarioFile, _> = serde_path_to_error::deserialize(&mut de);
    let err = match result {
        Ok(_) => de.end().err().map(|e| e.to_string())?,
        Err(err) => {
            let path = err.path().to_string();
            let inner = err.into_inner();
            let valid_json = value.is_some();
            if path == "." || inner.is_eof() || (inner.is_syntax() && !valid_json) {
                inner.to_string()
            } else if inner.is_syntax() {
                // A well-formed value of the wrong type where serde_json wanted an enum's name.
                let expected = if path.ends_with(".kind") {
                    "expected \"box\" or \"ball\""
                } else {
                    "wrong type of value"
                };
                format!(
                    "{path}: {expected} at line {} column {}",
                    inner.line(),
                    inner.column()
                )
            } else {
                format!("{path}: {}", plain(&inner.to_string()))
            }
        }
    };
    Some(err.replace('\n', " "))
}

/// The first place, as a field path, where the file has an array and a scenario an object.
fn array_for_object(file: &serde_json::Value) -> Option<String> {
    use serde_json::Value;
    let objects = ["robot", "sonar", "bumper", "smpa", "doors", "fault"];
    for key in objects {
        if file.get(key).is_some_and(Value::is_array) {
            return Some(key.into());
        }
    }
    let items = file.get("interferences").and_then(Value::as_array)?;
    let index = items.iter().position(Value::is_array)?;
    Some(format!("interferences[{index}]"))
}

/// serde's message without the program's own type names: `expected struct FaultFile` is an
/// object, `invalid type: floating point `1.8e19`, expected u64` a whole number out of range.
fn plain(message: &str) -> String {
    let at = message.find(" at line ").map_or("", |i| &message[i..]);
    for (ty, max) in [
        ("u64", u64::MAX),
        ("u32", u64::from(u32::MAX)),
        ("u16", u64::from(u16::MAX)),
    ] {
        if message.contains(&format!("expected {ty}")) {
            return format!("must be a whole number from 0 to {max}{at}");
        }
    }
    match message.find("expected struct ") {
        Some(i) => {
            let rest = &message[i + "expected struct ".len()..];
            let end = rest
                .find(|c: char| !c.is_alphanumeric())
                .unwrap_or(rest.len());
            format!("{}expected an object{}", &message[..i], &rest[end..])
        }
        None => message.to_owned(),
    }
}
