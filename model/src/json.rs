//! Strict JSON for host tools' input files (feature `std`): `psmpa-sim`'s scenarios and
//! missions, and the mission files `include_mission!` reads when a robot is built.
//!
//! The scenario and mission loaders use `serde-json-core`, which is lenient where a host tool
//! should not be (a leading `+`, raw control characters and invalid UTF-8 in strings, duplicate
//! keys) and cannot decode UTF-16 surrogate pairs. [`strict`] checks a file as RFC 8259 JSON
//! with `serde_json` first, naming the field at fault, and then decodes the `\u` escapes that
//! stand for ordinary characters, so the loaders downstream see the real text.

use std::borrow::Cow;
use std::borrow::ToOwned;
use std::collections::HashSet;
use std::fmt;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec;

use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};

/// What makes a file not strict JSON.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Problem {
    /// The file is empty or only whitespace.
    Empty,
    /// A byte order mark before the value.
    ByteOrderMark,
    /// A raw control character (U+0000 to U+001F) inside a string.
    ControlCharacter(u8),
    /// An object has this key more than once.
    DuplicateKey(String),
    /// A number written with a leading `+`.
    LeadingPlus,
    /// Bytes that are not UTF-8; the first of them.
    InvalidUtf8(u8),
    /// A `\u` escape of one half of a UTF-16 surrogate pair without the other half.
    LoneSurrogate,
    /// Arrays and objects nested deeper than `serde_json` allows.
    TooDeep,
    /// The file ends inside a value; what was being read.
    UnexpectedEnd(&'static str),
    /// More text after the value.
    TrailingText,
    /// Any other syntax error, in `serde_json`'s words.
    Syntax(String),
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty => f.write_str("the file is empty: expected a JSON value"),
            Self::ByteOrderMark => f.write_str(
                "a byte order mark (U+FEFF) is not JSON; save the file as UTF-8 without one",
            ),
            Self::ControlCharacter(b) => write!(
                f,
                "a control character (U+{b:04X}) in a string is not JSON; write it as {}",
                escape_for(*b)
            ),
            Self::DuplicateKey(key) => {
                write!(f, "the key \"{}\" appears twice", printable(key))
            }
            Self::LeadingPlus => {
                f.write_str("a number cannot start with \"+\" in JSON; leave the sign out")
            }
            Self::InvalidUtf8(b) => write!(f, "not valid UTF-8 (byte 0x{b:02X})"),
            Self::LoneSurrogate => f.write_str(
                "a \\u escape of half a UTF-16 surrogate pair without the other half is not a character",
            ),
            Self::TooDeep => f.write_str("arrays and objects nested more than 128 deep"),
            Self::UnexpectedEnd(what) => write!(f, "the file ends inside {what}"),
            Self::TrailingText => f.write_str("more text after the end of the JSON value"),
            Self::Syntax(what) => write!(f, "malformed JSON: {}", printable(what)),
        }
    }
}

/// How to write control character `b` in a JSON string.
fn escape_for(b: u8) -> String {
    match b {
        b'\n' => "\\n".into(),
        b'\r' => "\\r".into(),
        b'\t' => "\\t".into(),
        0x08 => "\\b".into(),
        0x0C => "\\f".into(),
        _ => format!("\\u{b:04x}"),
    }
}

/// Why a file is not strict JSON, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JsonError {
    /// The field at fault (`sensors[2].name`), if the problem is inside one.
    pub field: Option<String>,
    /// What is wrong.
    pub problem: Problem,
    /// Line, from 1.
    pub line: usize,
    /// Column in bytes, as `serde_json` counts it.
    pub column: usize,
}

impl fmt::Display for JsonError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(field) = &self.field {
            write!(f, "{field}: ")?;
        }
        write!(
            f,
            "{} (line {} column {})",
            self.problem, self.line, self.column
        )
    }
}

impl std::error::Error for JsonError {}

/// Checks `bytes` as strict RFC 8259 JSON with no duplicate keys, and returns it with every
/// `\u` escape that stands for an ordinary character decoded to UTF-8 (a surrogate pair to one
/// character). Escapes of `"`, `\` and control characters stay as they are, so the result is
/// still JSON and no control character appears in it raw; everything else is copied byte for
/// byte, so line numbers do not change. Borrows when there is nothing to decode.
pub fn strict(bytes: &[u8]) -> Result<Cow<'_, [u8]>, JsonError> {
    validate(bytes)?;
    Ok(decode_escapes(bytes))
}

/// [`strict`] for the file `file`, its error as the one line the command line prints.
pub fn strict_file<'b>(file: &std::path::Path, bytes: &'b [u8]) -> Result<Cow<'b, [u8]>, String> {
    strict(bytes).map_err(|e| format!("{}: {e}", file.display()))
}

/// The most steps of a path an error shows in full.
const SHOWN_STEPS: usize = 8;

/// One step of the path to a value.
enum Step {
    Key(String),
    Index(usize),
}

/// The walk's state: the path to the value being read and a problem found by the walk itself
/// (serde_json's own errors carry no path).
#[derive(Default)]
struct Walk {
    path: Vec<Step>,
    duplicate: Option<String>,
}

impl Walk {
    fn field(&self) -> Option<String> {
        let mut out = String::new();
        // A path as deep as the nesting limit is 128 steps: its first few say where.
        let shown = if self.path.len() > SHOWN_STEPS {
            SHOWN_STEPS / 2
        } else {
            SHOWN_STEPS
        };
        for step in self.path.iter().take(shown) {
            match step {
                Step::Key(k) => {
                    if !out.is_empty() {
                        out.push('.');
                    }
                    out.push_str(&printable(k));
                }
                Step::Index(i) => out.push_str(&format!("[{i}]")),
            }
        }
        if self.path.len() > shown {
            out.push_str(&format!("... ({} levels deep)", self.path.len()));
        }
        (!out.is_empty()).then_some(out)
    }
}

/// Any value; records the path on the way down and leaves it in place on an error.
struct Value<'w>(&'w mut Walk);

impl<'de> DeserializeSeed<'de> for Value<'_> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Value<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a JSON value")
    }
    fn visit_bool<E: de::Error>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E: de::Error>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E: de::Error>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E: de::Error>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E: de::Error>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E: de::Error>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut index = 0;
        while seq
            .next_element_seed(Element(&mut *self.0, index))?
            .is_some()
        {
            index += 1;
        }
        Ok(())
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let walk = self.0;
        let mut seen = HashSet::new();
        while let Some(key) = map.next_key_seed(Key)? {
            walk.path.push(Step::Key(key.clone()));
            if !seen.insert(key.clone()) {
                walk.duplicate = Some(key);
                return Err(de::Error::custom("duplicate key"));
            }
            map.next_value_seed(Value(&mut *walk))?;
            walk.path.pop();
        }
        Ok(())
    }
}

/// Element `.1` of an array: pushed only once the element starts, so an error between elements
/// names the array.
struct Element<'w>(&'w mut Walk, usize);

impl<'de> DeserializeSeed<'de> for Element<'_> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        let Element(walk, index) = self;
        walk.path.push(Step::Index(index));
        Value(&mut *walk).deserialize(d)?;
        walk.path.pop();
        Ok(())
    }
}

/// An object key, decoded (and so checked by serde_json).
struct Key;

impl<'de> DeserializeSeed<'de> for Key {
    type Value = String;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<String, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for Key {
    type Value = String;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a key")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<String, E> {
        Ok(v.to_owned())
    }
}

fn validate(bytes: &[u8]) -> Result<(), JsonError> {
    let mut walk = Walk::default();
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let result = Value(&mut walk)
        .deserialize(&mut de)
        .and_then(|()| de.end());
    let Err(e) = result else {
        return Ok(());
    };
    let (line, column) = (e.line(), e.column());
    let problem = match walk.duplicate.take() {
        Some(key) => Problem::DuplicateKey(key),
        None => classify(bytes, &e),
    };
    // serde_json reports a raw newline in a string on the next line, and a bad UTF-8 byte
    // after its string: point at the byte itself.
    let at = match problem {
        Problem::ControlCharacter(_) => Some(blamed(bytes, line, column)),
        Problem::InvalidUtf8(_) => std::str::from_utf8(bytes).err().map(|u| u.valid_up_to()),
        _ => None,
    };
    let (line, column) = at.map_or((line, column), |i| position(bytes, i));
    Err(JsonError {
        field: walk.field(),
        problem,
        line,
        column,
    })
}

/// What a serde_json syntax error means, in terms a person editing the file can act on.
fn classify(bytes: &[u8], e: &serde_json::Error) -> Problem {
    let full = e.to_string();
    let suffix = format!(" at line {} column {}", e.line(), e.column());
    let message = full.strip_suffix(&suffix).unwrap_or(&full);
    let at = bytes.get(blamed(bytes, e.line(), e.column())).copied();
    match message {
        _ if bytes.iter().all(u8::is_ascii_whitespace) => Problem::Empty,
        "control character (\\u0000-\\u001F) found while parsing a string" => {
            Problem::ControlCharacter(at.filter(|b| *b < 0x20).unwrap_or(0))
        }
        "invalid unicode code point" => Problem::InvalidUtf8(first_invalid_utf8(bytes)),
        "lone leading surrogate in hex escape" | "unexpected end of hex escape" => {
            Problem::LoneSurrogate
        }
        "recursion limit exceeded" => Problem::TooDeep,
        "trailing characters" => Problem::TrailingText,
        "EOF while parsing a list" => Problem::UnexpectedEnd("a list"),
        "EOF while parsing an object" => Problem::UnexpectedEnd("an object"),
        "EOF while parsing a string" => Problem::UnexpectedEnd("a string"),
        "EOF while parsing a value" => Problem::UnexpectedEnd("a value"),
        _ if bytes.starts_with(b"\xEF\xBB\xBF") && e.line() == 1 && e.column() <= 1 => {
            Problem::ByteOrderMark
        }
        "expected value" if at == Some(b'+') => Problem::LeadingPlus,
        _ if at.is_some_and(|b| b >= 0x80) && std::str::from_utf8(bytes).is_err() => {
            Problem::InvalidUtf8(first_invalid_utf8(bytes))
        }
        "expected value" => match at {
            Some(b) if b.is_ascii_graphic() => Problem::Syntax(format!(
                "expected a JSON value (a string, number, object, array, true, false or null), found `{}`",
                char::from(b)
            )),
            _ => Problem::Syntax("expected a JSON value".into()),
        },
        other => Problem::Syntax(other.into()),
    }
}

fn first_invalid_utf8(bytes: &[u8]) -> u8 {
    std::str::from_utf8(bytes)
        .err()
        .and_then(|e| bytes.get(e.valid_up_to()).copied())
        .unwrap_or(0)
}

/// The byte serde_json's `line`/`column` point just past: the last one it read.
fn blamed(bytes: &[u8], line: usize, column: usize) -> usize {
    // Line `line` starts after newline number `line - 1`.
    let start = match line.checked_sub(2) {
        None => 0,
        Some(n) => bytes
            .iter()
            .enumerate()
            .filter(|(_, b)| **b == b'\n')
            .nth(n)
            .map_or(bytes.len(), |(i, _)| i + 1),
    };
    (start + column).saturating_sub(1)
}

/// Line and column (from 1, in bytes) of byte `i`.
fn position(bytes: &[u8], i: usize) -> (usize, usize) {
    let before = bytes.get(..i).unwrap_or(bytes);
    let line = 1 + before.iter().filter(|b| **b == b'\n').count();
    let start = before
        .iter()
        .rposition(|b| *b == b'\n')
        .map_or(0, |n| n + 1);
    (line, i - start + 1)
}

/// `text` with every control character written as a JSON escape: safe on a terminal, one line.
pub fn printable(text: &str) -> Cow<'_, str> {
    if !text.chars().any(hidden) {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        if hidden(c) {
            out.push_str(&format!("\\u{:04x}", u32::from(c)));
        } else {
            out.push(c);
        }
    }
    Cow::Owned(out)
}

use crate::domain::hidden;

/// Decodes the `\u` escapes of valid JSON that stand for ordinary characters.
fn decode_escapes(bytes: &[u8]) -> Cow<'_, [u8]> {
    let mut out = Vec::new();
    let mut copied = 0;
    let mut in_string = false;
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        match (in_string, b) {
            (false, b'"') => in_string = true,
            (true, b'"') => in_string = false,
            (true, b'\\') => {
                let (len, decoded) = escape_at(bytes, i);
                if let Some(c) = decoded.filter(|c| !matches!(c, '"' | '\\') && !c.is_control()) {
                    out.extend_from_slice(bytes.get(copied..i).unwrap_or_default());
                    out.extend_from_slice(c.encode_utf8(&mut [0; 4]).as_bytes());
                    copied = i + len;
                }
                i += len;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    if copied == 0 {
        return Cow::Borrowed(bytes);
    }
    out.extend_from_slice(bytes.get(copied..).unwrap_or_default());
    Cow::Owned(out)
}

/// The length of the escape sequence starting at `bytes[i]` (a backslash), and the character
/// it stands for if it is a `\u` escape (a surrogate pair counts as one escape).
fn escape_at(bytes: &[u8], i: usize) -> (usize, Option<char>) {
    if bytes.get(i + 1) != Some(&b'u') {
        return (2, None);
    }
    let Some(high) = hex4(bytes, i + 2) else {
        return (2, None);
    };
    if !(0xD800..0xDC00).contains(&high) {
        return (6, char::from_u32(high));
    }
    let low = (bytes.get(i + 6..i + 8) == Some(b"\\u"))
        .then(|| hex4(bytes, i + 8))
        .flatten()
        .filter(|low| (0xDC00..0xE000).contains(low));
    match low {
        Some(low) => (
            12,
            char::from_u32(0x1_0000 + ((high - 0xD800) << 10) + (low - 0xDC00)),
        ),
        None => (6, None),
    }
}

/// The four hex digits at `bytes[at..]`.
fn hex4(bytes: &[u8], at: usize) -> Option<u32> {
    let digits = bytes.get(at..at + 4)?;
    digits
        .iter()
        .try_fold(0, |n, d| char::from(*d).to_digit(16).map(|v| n * 16 + v))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(json: &str) -> Cow<'_, [u8]> {
        strict(json.as_bytes()).unwrap()
    }

    fn err(json: &[u8]) -> JsonError {
        let e = strict(json).unwrap_err();
        let line = e.to_string();
        assert!(
            !line.contains('\n') && !line.chars().any(char::is_control),
            "{line}"
        );
        e
    }

    /// Control characters and invisible format characters are shown escaped; other text,
    /// accents included, as it is.
    #[test]
    fn printable_escapes_what_a_terminal_would_hide_or_act_on() {
        assert_eq!(printable("café"), "café");
        assert_eq!(printable("a\u{1b}[31mb"), "a\\u001b[31mb");
        assert_eq!(printable("abc\u{202e}fed"), "abc\\u202efed");
        assert_eq!(printable("go\u{200b}door"), "go\\u200bdoor");
        assert_eq!(printable("door\u{ad}"), "door\\u00ad");
        assert_eq!(printable("a\u{e0041}"), "a\\ue0041");
    }

    #[test]
    fn a_bmp_escape_is_decoded() {
        assert_eq!(
            &*ok(r#"{"a":"caf\u00e9 \u00E9"}"#),
            "{\"a\":\"café é\"}".as_bytes()
        );
    }

    #[test]
    fn a_surrogate_pair_becomes_one_character() {
        let out = ok(r#"{"name": "\ud83d\ude00!"}"#);
        assert_eq!(&*out, "{\"name\": \"😀!\"}".as_bytes());
        // In keys too: the loaders match keys as text.
        assert_eq!(&*ok(r#"{"n\u0061me": 1}"#), br#"{"name": 1}"#);
    }

    #[test]
    fn quotes_backslashes_and_control_characters_stay_escaped() {
        let json = r#"{"a": "\" \\ \u0022 \u005C \u0000 \u001b \u007f \u009b \n \/"}"#;
        assert!(matches!(ok(json), Cow::Borrowed(_)));
        // An escaped backslash followed by `u0041` is not an escape of `A`.
        assert!(matches!(ok(r#"["\\u0041"]"#), Cow::Borrowed(_)));
        // Outside strings there is nothing to decode.
        assert!(matches!(ok("[1, 2.5, true, null]"), Cow::Borrowed(_)));
    }

    #[test]
    fn decoding_keeps_lines_and_gives_strict_json_again() {
        let json = "{\n\"a\": \"\\u00e9\\ud83d\\ude00\\u0001\",\n\"b\": [\"\\u20AC\"]\n}";
        let out = ok(json);
        assert!(matches!(out, Cow::Owned(_)));
        let count = |b: &[u8]| b.iter().filter(|c| **c == b'\n').count();
        assert_eq!(count(&out), count(json.as_bytes()));
        assert!(matches!(strict(&out), Ok(Cow::Borrowed(_))));
        let text = std::str::from_utf8(&out).unwrap();
        assert!(text.contains("é😀\\u0001") && text.contains("€"), "{text}");
    }

    #[test]
    fn a_lone_surrogate_is_rejected_with_its_field() {
        for json in [
            r#"{"x": {"name": "\ud83d"}}"#,
            r#"{"x": {"name": "\ud83d\u0041"}}"#,
            r#"{"x": {"name": "\ude00"}}"#,
        ] {
            let e = err(json.as_bytes());
            assert_eq!(e.field.as_deref(), Some("x.name"), "{json}: {e}");
            assert_eq!(e.problem, Problem::LoneSurrogate, "{json}: {e}");
        }
    }

    #[test]
    fn raw_control_characters_are_named_with_their_field_and_line() {
        for (byte, escape) in [
            (1u8, "\\u0001"),
            (0x1b, "\\u001b"),
            (b'\n', "\\n"),
            (0, "\\u0000"),
        ] {
            let mut json = b"{\"s\": [{\"k\": 1},\n {\"name\": \"a".to_vec();
            json.push(byte);
            json.extend_from_slice(b"b\"}]}");
            let e = err(&json);
            assert_eq!(e.field.as_deref(), Some("s[1].name"), "{e}");
            assert_eq!(e.problem, Problem::ControlCharacter(byte), "{e}");
            assert_eq!((e.line, e.column), (2, 13), "{e}");
            assert!(e.to_string().contains(escape), "{e}");
        }
    }

    #[test]
    fn a_leading_plus_is_rejected() {
        let e = err(b"{\"door_m\": +1}");
        assert_eq!(e.field.as_deref(), Some("door_m"));
        assert_eq!(e.problem, Problem::LeadingPlus);
        assert_eq!((e.line, e.column), (1, 12));
    }

    #[test]
    fn invalid_utf8_is_named_as_such() {
        let e = err(b"{\"a\": 1,\n \"name\": \"x\xFFy\"}");
        assert_eq!(e.field.as_deref(), Some("name"));
        assert_eq!(e.problem, Problem::InvalidUtf8(0xFF));
        assert_eq!((e.line, e.column), (2, 12));
        assert_eq!(err(b"[1, \xFF]").problem, Problem::InvalidUtf8(0xFF));
    }

    #[test]
    fn duplicate_keys_are_rejected_at_every_level() {
        let e = err(br#"{"name": "a", "name": "b"}"#);
        assert_eq!(e.field.as_deref(), Some("name"));
        assert_eq!(e.problem, Problem::DuplicateKey("name".into()));
        let e = err(br#"{"a": [{"b": 1}, {"b": 1, "c": {"d": 1, "d": 2}}]}"#);
        assert_eq!(e.field.as_deref(), Some("a[1].c.d"));
        assert_eq!(e.problem, Problem::DuplicateKey("d".into()));
        // The same key after decoding is the same key.
        let e = err(br#"{"name": 1, "n\u0061me": 2}"#);
        assert_eq!(e.problem, Problem::DuplicateKey("name".into()));
        // Equal keys in different objects are fine.
        ok(r#"{"a": {"k": 1}, "b": {"k": 1}, "k": [{"k": 1}, {"k": 2}]}"#);
    }

    #[test]
    fn other_problems_have_their_own_words() {
        assert_eq!(err(b"").problem, Problem::Empty);
        assert_eq!(err(b" \n ").problem, Problem::Empty);
        assert_eq!(err(b"\xEF\xBB\xBF{}").problem, Problem::ByteOrderMark);
        assert_eq!(err(b"{} x").problem, Problem::TrailingText);
        assert_eq!(err(&[b'['; 200]).problem, Problem::TooDeep);
        // Past the limit, the path shows where it starts and how deep it went, not 128 steps.
        let deep = format!("{{\"description\": {}", "[".repeat(200));
        let e = err(deep.as_bytes());
        assert_eq!(
            e.field.as_deref(),
            Some("description[0][0][0]... (127 levels deep)")
        );
        let e = err(b"{\"a\": [1, 2");
        assert_eq!(e.problem, Problem::UnexpectedEnd("a list"));
        assert_eq!(e.field.as_deref(), Some("a"));
        let e = err(br#"{"a": [1, 2,]}"#);
        assert_eq!(e.problem, Problem::Syntax("trailing comma".into()));
        let e = err(br#"{"a": NaN}"#);
        assert!(
            e.to_string()
                .starts_with("a: malformed JSON: expected a JSON value"),
            "{e}"
        );
        // A control character in a key names the object that holds it.
        let e = err(b"{\"a\": {\"b\x01\": 1}}");
        assert_eq!(e.field.as_deref(), Some("a"));
        assert_eq!(e.problem, Problem::ControlCharacter(1));
    }

    #[test]
    fn the_message_is_one_line_with_field_problem_and_position() {
        let e = err(b"{\"name\": \"a\x01\"}");
        assert_eq!(
            e.to_string(),
            "name: a control character (U+0001) in a string is not JSON; write it as \\u0001 (line 1 column 12)"
        );
        // A key with an escaped control character is shown escaped.
        let e = err(br#"{"a\u001bb": 1, "a\u001bb": 2}"#);
        assert!(
            e.to_string()
                .starts_with("a\\u001bb: the key \"a\\u001bb\""),
            "{e}"
        );
    }
}
