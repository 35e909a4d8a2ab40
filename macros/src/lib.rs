//! # psmpa-macros: missions compiled into a robot's Rust
//!
//! [`include_mission!`] reads a mission file when the robot is built, checks it as
//! `psmpa-sim check` does (the same code: `psmpa_model::check`), and generates a module with
//! the mission's names as enums, its capacities, its runtime's type and the mission itself, a
//! `static` built at compile time: nothing is parsed when the robot boots, and a mistake in the
//! file is a compile error. Use it through `psmpa_core::include_mission!`, which re-exports it.

#![deny(missing_docs)]
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};

use proc_macro::TokenStream;
use proc_macro2::{Span, TokenStream as Tokens};
use psmpa_model::action::SensorMode;
use psmpa_model::check::{self, Large};
use psmpa_model::facts::FactSetOf;
use quote::{format_ident, quote};
use syn::parse::{Parse, ParseStream};
use syn::{Attribute, Ident, LitInt, LitStr, Token, Visibility};

/// The widest fact sets a compiled mission may have: 4 words, 256 facts (what the checks load).
const MAX_WORDS: usize = 4;
/// The most facts a compiled mission may name.
const MAX_FACTS: usize = 64 * MAX_WORDS;
/// The most keys a data store may hold: a `psmpa_core::store::Key` is a `u8`.
const MAX_KEYS: u64 = 256;

/// `VIS mod NAME = "PATH"` and, optionally, `, keys = N`.
struct Input {
    /// The module's attributes (its documentation, a `cfg`).
    attrs: Vec<Attribute>,
    vis: Visibility,
    name: Ident,
    path: LitStr,
    keys: Option<LitInt>,
}

impl Parse for Input {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis = input.parse()?;
        input.parse::<Token![mod]>()?;
        let name = input.parse()?;
        input.parse::<Token![=]>()?;
        let path = input.parse()?;
        let mut keys = None;
        if input.parse::<Option<Token![,]>>()?.is_some() && !input.is_empty() {
            let key: Ident = input.parse()?;
            if key != "keys" {
                return Err(syn::Error::new(
                    key.span(),
                    "expected `keys = N` (the keys each data store holds)",
                ));
            }
            input.parse::<Token![=]>()?;
            keys = Some(input.parse()?);
            input.parse::<Option<Token![,]>>()?;
        }
        Ok(Self {
            attrs,
            vis,
            name,
            path,
            keys,
        })
    }
}

/// Compiles a mission file into a module of the including crate:
///
/// ```ignore
/// psmpa_core::include_mission!(pub mod dock = "mission.json");
/// ```
///
/// `PATH` is relative to the including crate's `CARGO_MANIFEST_DIR`. The file is checked as
/// `psmpa-sim check` checks one (strict JSON, every name resolved, capacities, a reachable
/// goal), with up to 256 facts; an error is a compile error that names the field and the name
/// at fault (`mission.json: plans[0].body: unknown action "fly"`). Module `NAME` then holds:
///
/// * enums `Sensor`, `Action`, `Fact`, `Event`, `Plan`: one variant a name, in UpperCamelCase
///   (`go to door` is `GoToDoor`), with `name()`, `id()`, `from_id()`, `ALL`, `Display` and,
///   with psmpa-core's `defmt` feature, `defmt::Format` (the original names);
/// * `Caps`, the runtime's capacities from the mission (`keys = N` sets the keys each data
///   store holds; by default a sensor's reading and all its pairs);
/// * `Mission`, its type, and `MISSION`, a `static` built at compile time;
/// * `Runtime<'r, P, T = ()>`, the runtime of platform `P` for this mission, a type with its
///   constructor: `dock::Runtime::new(&dock::MISSION, &robot, (), config)`.
///
/// A robot names its sensors and actions by the enums (`type Id = dock::Sensor;` in its
/// `Sensor` implementation, `type Id = dock::Action;` in its `Actuator`), so its `match` is
/// checked to be exhaustive. Attributes before `mod` (`///` documentation, a `#[cfg(..)]`)
/// go on the module.
#[proc_macro]
pub fn include_mission(input: TokenStream) -> TokenStream {
    let input = syn::parse_macro_input!(input as Input);
    match expand(&input) {
        Ok(tokens) => tokens.into(),
        Err(e) => e.to_compile_error().into(),
    }
}

fn expand(input: &Input) -> syn::Result<Tokens> {
    let span = input.path.span();
    let given = input.path.value();
    let root = std::env::var_os("CARGO_MANIFEST_DIR").map_or_else(PathBuf::new, PathBuf::from);
    let file = root.join(&given);
    // A regular file of at most 1 MiB, as psmpa-sim reads one: a FIFO would block the
    // compiler for ever, `/dev/zero` fill its memory.
    let bytes = check::read_input(&file, "mission").map_err(|e| syn::Error::new(span, e))?;
    let keys = match &input.keys {
        Some(k) => {
            // A key is a `u8`: 256 distinct ones at most.
            let n = k
                .base10_parse::<u64>()
                .ok()
                .filter(|n| (1..=MAX_KEYS).contains(n))
                .ok_or_else(|| {
                    syn::Error::new(
                        k.span(),
                        format!(
                            "keys = {}: a data store holds from 1 to {MAX_KEYS} keys (a key is a u8)",
                            k.base10_digits()
                        ),
                    )
                })? as usize;
            quote!(#n)
        }
        None => quote!({ ::psmpa_core::platform::MAX_PAIRS + 1 }),
    };
    // Computed here: a `const fn` over a large file's bytes exceeds the compiler's budget.
    let hash = psmpa_model::mission::mission_hash(&bytes);
    let descriptions =
        Descriptions::of(&bytes).map_err(|e| syn::Error::new(span, format!("{given}: {e}")))?;
    check::check::<_, MAX_WORDS, MAX_FACTS>(Path::new(&given), &bytes, |m| {
        generate(input, m, &file, &keys, hash, &descriptions)
    })
    .map_err(|e| syn::Error::new(span, e))?
}

/// An UpperCamelCase identifier for a mission's name: words split at anything that cannot
/// continue a Rust identifier (`go to door`, `path_clear`, `GetIn Kitchen` are `GoToDoor`,
/// `PathClear`, `GetInKitchen`; `x²` is `X`); `N` before anything that cannot start one (a
/// digit, `٣`); `Self_` for `self`.
fn variant(name: &str) -> String {
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

/// The variants of a table's names; a compile error when two names make one identifier.
fn variants(table: &str, names: &[&str], span: Span) -> syn::Result<Vec<Ident>> {
    let mut seen: Vec<(String, &str)> = Vec::new();
    let mut out = Vec::new();
    for name in names {
        let v = variant(name);
        if let Some((_, other)) = seen.iter().find(|(s, _)| *s == v) {
            return Err(syn::Error::new(
                span,
                format!(
                    "{table} \"{}\" and \"{}\" would both be the variant {v}: rename one",
                    check::printable(other),
                    check::printable(name)
                ),
            ));
        }
        // Not a raw identifier: a name is never a keyword once it starts upper case. Parsed,
        // not built: what is not an identifier is an error naming it, never a panic.
        let ident = syn::parse_str::<Ident>(&v).map_err(|_| {
            syn::Error::new(
                span,
                format!(
                    "{table} \"{}\" makes no Rust identifier ({v}): rename it",
                    check::printable(name)
                ),
            )
        })?;
        out.push(Ident::new(&ident.to_string(), span));
        seen.push((v, name));
    }
    Ok(out)
}

/// `FactSetOf<W>` of the mission's first `w` words.
fn facts(set: FactSetOf<MAX_WORDS>, w: usize) -> Tokens {
    let words = set.words();
    let words = words.iter().take(w);
    quote!(::psmpa_core::FactSetOf::<W>::from_words([#(#words),*]))
}

fn millis(d: embassy_time::Duration) -> u64 {
    d.as_millis()
}

/// The description strings of a mission's facts (`fact_descriptions`), sensors, actions and
/// plans (`description`), by index (`None`: none, or one that is not a string), for the
/// variants' doc comments and `description()`.
struct Descriptions {
    facts: Vec<Option<String>>,
    sensors: Vec<Option<String>>,
    actions: Vec<Option<String>>,
    plans: Vec<Option<String>>,
}

impl Descriptions {
    /// From the mission file's bytes (already checked: anything unreadable has none); an
    /// entry of `fact_descriptions` that names no fact is an error (a typo would lose it).
    fn of(bytes: &[u8]) -> Result<Self, String> {
        let v: serde_json::Value = serde_json::from_slice(bytes).unwrap_or_default();
        if let Some(described) = v.get("fact_descriptions") {
            let facts: Vec<&str> = v["facts"]
                .as_array()
                .map_or_else(Vec::new, |f| f.iter().filter_map(|n| n.as_str()).collect());
            let Some(map) = described.as_object() else {
                return Err(
                    "fact_descriptions: an object from a fact's name to its description".to_owned(),
                );
            };
            if let Some(name) = map.keys().find(|k| !facts.contains(&k.as_str())) {
                return Err(format!(
                    "fact_descriptions: `{name}` is not a fact of the mission (not in `facts`)"
                ));
            }
        }
        let of = |section: &str| -> Vec<Option<String>> {
            v[section].as_array().map_or_else(Vec::new, |items| {
                items
                    .iter()
                    .map(|i| i["description"].as_str().map(str::to_owned))
                    .collect()
            })
        };
        // Facts are names in a list: theirs are an object by name.
        let facts = v["facts"].as_array().map_or_else(Vec::new, |names| {
            names
                .iter()
                .map(|n| {
                    let name = n.as_str()?;
                    v["fact_descriptions"][name].as_str().map(str::to_owned)
                })
                .collect()
        });
        Ok(Self {
            facts,
            sensors: of("sensors"),
            actions: of("actions"),
            plans: of("plans"),
        })
    }
}

/// One of the generated enums: its variants, ids and names.
fn names_enum(
    what: &str,
    ty: &Ident,
    id: Tokens,
    repr: Tokens,
    variants: &[Ident],
    names: &[&str],
    described: &[Option<String>],
) -> Tokens {
    let n = variants.len();
    let index: Vec<usize> = (0..n).collect();
    let doc = format!(
        "The mission's {what}s, one variant a name; `name()` is the name the mission gives it."
    );
    let variant_docs: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let name = format!("`{}`", s.replace('`', "'"));
            match described.get(i).cloned().flatten() {
                Some(d) => format!("{name}: {d}"),
                None => name,
            }
        })
        .collect();
    let descriptions: Vec<Tokens> = (0..n)
        .map(|i| match described.get(i).cloned().flatten() {
            Some(d) => quote!(::core::option::Option::Some(#d)),
            None => quote!(::core::option::Option::None),
        })
        .collect();
    // An enum with no variants has no representation to give (E0084): a mission with no
    // sensors or no plans has no value of that type at all.
    let repr_attr = (n > 0).then(|| quote!(#[repr(#repr)]));
    quote! {
        #[doc = #doc]
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
        #repr_attr
        pub enum #ty {
            #( #[doc = #variant_docs] #variants = #index as #repr, )*
        }

        impl #ty {
            /// Every one, in the mission's order.
            pub const ALL: [Self; #n] = [#(Self::#variants),*];

            /// The name the mission gives it.
            pub const fn name(self) -> &'static str {
                match self {
                    #( Self::#variants => #names, )*
                }
            }

            /// The `description` the mission gives it, if it gives a string one.
            pub const fn description(self) -> ::core::option::Option<&'static str> {
                match self {
                    #( Self::#variants => #descriptions, )*
                }
            }

            /// Its id in the mission.
            pub const fn id(self) -> #id {
                match self {
                    #( Self::#variants => <#id>::of::<#index>(), )*
                }
            }

            /// The one of id `id`, if the mission has it.
            pub const fn from_id(id: #id) -> ::core::option::Option<Self> {
                match id.index() {
                    #( #index => ::core::option::Option::Some(Self::#variants), )*
                    _ => ::core::option::Option::None,
                }
            }
        }

        impl ::psmpa_core::platform::FromId<#id> for #ty {
            fn from_id(id: #id) -> ::core::option::Option<Self> {
                Self::from_id(id)
            }
        }

        impl ::core::fmt::Display for #ty {
            fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                f.write_str(self.name())
            }
        }

        ::psmpa_core::__format_as_name!(#ty);
    }
}

fn generate(
    input: &Input,
    m: &Large<'_, MAX_WORDS, MAX_FACTS>,
    file: &Path,
    keys: &Tokens,
    hash: u64,
    descriptions: &Descriptions,
) -> syn::Result<Tokens> {
    let span = input.path.span();
    let d = &m.domain;
    let fact_names = d.fact_names();
    let event_names = d.event_names();
    let sensor_names: Vec<&str> = d.sensors().iter().map(|s| s.name).collect();
    let action_names: Vec<&str> = d.actions().iter().map(|a| a.name).collect();
    let plans = m.library.plans();
    let plan_names: Vec<&str> = plans.iter().map(|p| p.name).collect();
    let (nf, ns, na, np) = (
        fact_names.len(),
        sensor_names.len(),
        action_names.len(),
        plans.len(),
    );
    let w = nf.div_ceil(64).max(1);
    let l = plans.iter().map(|p| p.body.len()).max().unwrap_or(0).max(1);

    let fact_v = variants("facts", fact_names, span)?;
    let event_v = variants("events", event_names, span)?;
    let sensor_v = variants("sensors", &sensor_names, span)?;
    let action_v = variants("actions", &action_names, span)?;
    let plan_v = variants("plans", &plan_names, span)?;

    let enums = [
        names_enum(
            "fact",
            &format_ident!("Fact"),
            quote!(::psmpa_core::FactId),
            quote!(u16),
            &fact_v,
            fact_names,
            &descriptions.facts,
        ),
        names_enum(
            "event",
            &format_ident!("Event"),
            quote!(::psmpa_core::EventId),
            quote!(u8),
            &event_v,
            event_names,
            &[],
        ),
        names_enum(
            "sensor",
            &format_ident!("Sensor"),
            quote!(::psmpa_core::SensorId),
            quote!(u8),
            &sensor_v,
            &sensor_names,
            &descriptions.sensors,
        ),
        names_enum(
            "action",
            &format_ident!("Action"),
            quote!(::psmpa_core::ActionId),
            quote!(u16),
            &action_v,
            &action_names,
            &descriptions.actions,
        ),
        names_enum(
            "plan",
            &format_ident!("Plan"),
            quote!(::psmpa_core::PlanId),
            quote!(u8),
            &plan_v,
            &plan_names,
            &descriptions.plans,
        ),
    ];

    // Every period and timeout, checked against the crate's tick rate where it compiles.
    let mut durations: Vec<(String, u64)> = Vec::new();
    for s in d.sensors() {
        if let SensorMode::Cyclic { period } = s.mode {
            let what = format!("sensor `{}`: period_ms = {}", s.name, millis(period));
            durations.push((what, millis(period)));
        }
        let what = format!("sensor `{}`: timeout_ms = {}", s.name, millis(s.timeout));
        durations.push((what, millis(s.timeout)));
    }
    for a in d.actions() {
        if let Some(t) = a.max_violation {
            let what = format!("action `{}`: max_violation_ms = {}", a.name, millis(t));
            durations.push((what, millis(t)));
        }
    }
    let tick_checks = durations
        .iter()
        .filter(|(_, ms)| *ms > 0)
        .map(|(what, ms)| {
            let ms = proc_macro2::Literal::u64_unsuffixed(*ms);
            quote!(::psmpa_core::__tick_rate_check!(#what, #ms);)
        });

    let sensors = d.sensors().iter().map(|s| {
        let (name, pre, per) = (s.name, facts(s.pre, w), facts(s.per, w));
        let mode = match s.mode {
            SensorMode::Cyclic { period } => {
                let ms = millis(period);
                quote!(::psmpa_core::SensorMode::Cyclic { period: ::psmpa_core::embassy_time::Duration::from_millis(#ms) })
            }
            SensorMode::OneShot => quote!(::psmpa_core::SensorMode::OneShot),
            SensorMode::OnDemand => quote!(::psmpa_core::SensorMode::OnDemand),
        };
        let timeout = millis(s.timeout);
        quote!(::psmpa_core::SensorAction {
            name: #name,
            pre: #pre,
            per: #per,
            mode: #mode,
            timeout: ::psmpa_core::embassy_time::Duration::from_millis(#timeout),
        })
    });
    let actions = d.actions().iter().map(|a| {
        let (name, pre, add, del) = (a.name, facts(a.pre, w), facts(a.add, w), facts(a.del, w));
        let max_violation = match a.max_violation {
            Some(t) => {
                let ms = millis(t);
                quote!(::core::option::Option::Some(::psmpa_core::embassy_time::Duration::from_millis(#ms)))
            }
            None => quote!(::core::option::Option::None),
        };
        quote!(::psmpa_core::ActuatorAction {
            name: #name,
            pre: #pre,
            add: #add,
            del: #del,
            max_violation: #max_violation,
        })
    });
    let library = plans.iter().map(|p| {
        let (name, context, context_not) = (p.name, facts(p.context, w), facts(p.context_not, w));
        let trigger = p.trigger.index();
        let body = p.body.iter().map(|a| {
            let i = a.index();
            quote!(::psmpa_core::ActionId::of::<#i>())
        });
        quote!(::psmpa_core::Plan::from_parts(
            #name,
            ::psmpa_core::EventId::of::<#trigger>(),
            #context,
            #context_not,
            [#(#body),*],
        ))
    });
    let task_event = m.task.event.index();
    let (init, goal) = (facts(m.task.init, w), facts(m.task.goal, w));
    let mission_name = m.name;

    let vis = &input.vis;
    let module = &input.name;
    let file = file.to_string_lossy().into_owned();
    let doc = format!(
        "The mission `{}` of `{}`, compiled in: its names as enums, its capacities, its \
         runtime and the mission itself ({nf} facts, {} events, {ns} sensors, {na} actions, \
         {np} plans).",
        mission_name.replace('`', "'"),
        input.path.value(),
        event_names.len()
    );
    let attrs = &input.attrs;
    Ok(quote! {
        #(#attrs)*
        #[doc = #doc]
        #vis mod #module {
            /// The mission file's hash ([`psmpa_core::record::mission_hash`]): a flight
            /// recording names its mission with it.
            pub const HASH: u64 = #hash;
            // Included so that the crate is built again when the file changes.
            const _: &[u8] = ::core::include_bytes!(#file);

            /// Words in the mission's fact sets.
            pub const W: usize = #w;
            /// Facts the mission names.
            pub const NF: usize = #nf;
            /// Sensors.
            pub const NS: usize = #ns;
            /// Actions.
            pub const NA: usize = #na;
            /// Plans in the library.
            pub const NP: usize = #np;
            /// The longest plan body.
            pub const L: usize = #l;
            /// Keys each data store holds.
            pub const K: usize = #keys;

            /// The runtime's capacities, from the mission.
            pub type Caps = ::psmpa_core::Caps<
                ::psmpa_core::Sensors<NS>,
                ::psmpa_core::Actions<NA>,
                ::psmpa_core::Plans<NP>,
                ::psmpa_core::Body<L>,
                ::psmpa_core::Keys<K>,
                ::psmpa_core::Words<W>,
                ::psmpa_core::Facts<NF>,
            >;
            /// The mission's type.
            pub type Mission = ::psmpa_core::Mission<'static, NS, NA, NP, L, W, NF>;
            /// The runtime of platform `P` for this mission, tracing into `T`:
            /// `Runtime::new(&MISSION, &robot, (), config)`.
            pub type Runtime<'r, P, T = ()> =
                ::psmpa_core::Engine<'r, P, T, NS, NA, NP, L, K, W, NF>;

            #(#tick_checks)*

            #(#enums)*

            /// The mission, built at compile time from the file and checked there.
            pub static MISSION: Mission = ::psmpa_core::Mission {
                name: #mission_name,
                domain: ::psmpa_core::Domain::from_tables(
                    [#(#fact_names),*],
                    [#(#event_names),*],
                    [#(#sensors),*],
                    [#(#actions),*],
                ),
                library: ::psmpa_core::PlanLibrary::from_plans([#(#library),*]),
                task: ::psmpa_core::Task {
                    event: ::psmpa_core::EventId::of::<#task_event>(),
                    init: #init,
                    goal: #goal,
                },
            };
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_missions_hash_is_computed_here_not_by_the_compiler() {
        // About 600 KB (a long description): a `const fn` hash of it exceeds rustc's budget.
        let mission = include_str!("../../missions/fetch-tea.json");
        let big = mission.replacen(
            "\"description\": \"",
            &format!("\"description\": \"{}", "x".repeat(600_000)),
            1,
        );
        let file = std::env::temp_dir().join(format!("psmpa-big-{}.json", std::process::id()));
        std::fs::write(&file, &big).unwrap();
        let call = format!("mod big = {:?}", file.display().to_string());
        let tokens = expand(&syn::parse_str::<Input>(&call).unwrap());
        std::fs::remove_file(&file).unwrap();
        let text = tokens.unwrap().to_string();
        let hash = psmpa_model::mission::mission_hash(big.as_bytes());
        assert!(
            text.contains(&format!("HASH : u64 = {hash}u64")),
            "{}",
            &text[..400]
        );
        assert!(!text.contains("mission_hash ("));
    }

    #[test]
    fn every_name_makes_an_identifier_or_an_error() {
        for (name, v) in [
            ("go to door", "GoToDoor"),
            ("x²", "X"),
            ("٣x", "N٣x"),
            ("①", "Unnamed"),
            ("½cup", "Cup"),
            ("straße", "Straße"),
            ("self", "Self_"),
            ("3 m", "N3M"),
        ] {
            assert_eq!(variant(name), v);
            assert!(
                variants("facts", &[name], Span::call_site()).is_ok(),
                "{name}"
            );
        }
    }
}
