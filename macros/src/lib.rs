//! # psmpa-macros: missions compiled into a robot's Rust
//!
//! [`include_mission!`] reads a mission file when the robot is built, checks it as
//! `psmpa-sim check` does (the same code: `psmpa_model::check`), and generates a module with
//! the mission as a type (`dock::Dock`), its names as enums, its capacities, its runtime's type
//! and its tables, a `static` built at compile time (`TABLES`): nothing is parsed when the
//! robot boots, and a mistake in the file is a compile error. Use it through `psmpa_core::include_mission!`, which re-exports it.

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
/// at fault (``mission.json: plans[0].body: unknown action `fly` (not in `actions`)``). Module `NAME` then holds:
///
/// * enums `Sensor`, `Action`, `Fact`, `Event`, `Plan`: one variant a name, in UpperCamelCase
///   (`go to door` is `GoToDoor`), with `name()`, `id()`, `from_id()`, `ALL`, `Display` and,
///   with psmpa-core's `defmt` feature, `defmt::Format` (the original names);
/// * the mission as a type, named as the module in UpperCamelCase (`dock::Dock`), which
///   implements `psmpa_core::Mission`: its storage, its plans' states as constant tables
///   (Algorithm 2 at build time) and a sampler per sensor, specialised for its mode;
/// * `Runtime<'r, P, T = ()>`, the runtime of platform `P` for this mission:
///   `dock::Runtime::new(dock::Dock, &robot, (), config)`;
/// * `Run<'io>`, the action to run with its typed I/O (`match act.typed() { .. }`), and the
///   types it reads by: `sensor::Sonar`, `action::GoToDoor` (which sensors run beside it) and
///   `key::EchoUs` (the keys the mission declares, `"keys"` of a sensor or an action);
/// * `TABLES`, the mission's tables as a `static`, for tools that print names or plans;
/// * the capacities `NS`, `NA`, `NP`, `L`, `W`, `NF` and `K`, the keys each data store holds
///   (by default a sensor's sample and its declared keys, or an action's; `keys = N` gives
///   more room).
///
/// A robot implements `Sensor<dock::Dock>` and `Actuator<dock::Dock>`, matching on the
/// enums, so its `match` is checked to be exhaustive and a platform for another mission does
/// not compile. Attributes before `mod` (`///` documentation, a `#[cfg(..)]`) go on the
/// module.
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
    let keys_option = match &input.keys {
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
            Some(n)
        }
        None => None,
    };
    // Computed here: a `const fn` over a large file's bytes exceeds the compiler's budget.
    let hash = psmpa_model::mission::mission_hash(&bytes);
    let descriptions =
        Descriptions::of(&bytes).map_err(|e| syn::Error::new(span, format!("{given}: {e}")))?;
    check::check::<_, MAX_WORDS, MAX_FACTS>(Path::new(&given), &bytes, |m| {
        generate(input, m, &file, keys_option, hash, &descriptions)
    })
    .map_err(|e| syn::Error::new(span, e))?
}

use psmpa_model::check::variant;

/// A description as a variant's doc comment: one line of its words, so that no fence (```)
/// and no indented line makes it a code block, which rustdoc would run as a failing doctest.
fn doc_line(description: &str) -> String {
    description
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace("```", "'''")
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
    quote!(::psmpa_core::FactSetOf::<#w>::from_words([#(#words),*]))
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
    /// The keys each sensor and action declares for its data store (`"keys"`), by index.
    sensor_keys: Vec<Vec<String>>,
    action_keys: Vec<Vec<String>>,
}

impl Descriptions {
    /// From the mission file's bytes (already checked: anything unreadable has none); an
    /// entry of `fact_descriptions` that names no fact is an error (a typo would lose it).
    fn of(bytes: &[u8]) -> Result<Self, String> {
        let v: serde_json::Value = serde_json::from_slice(bytes).unwrap_or_default();
        // The check `psmpa-sim check` makes too: one verdict.
        check::fact_descriptions(&v)?;
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
        let keys = |section: &str| -> Vec<Vec<String>> {
            v[section].as_array().map_or_else(Vec::new, |items| {
                items
                    .iter()
                    .map(|i| {
                        i["keys"].as_array().map_or_else(Vec::new, |k| {
                            k.iter()
                                .filter_map(|n| n.as_str().map(str::to_owned))
                                .collect()
                        })
                    })
                    .collect()
            })
        };
        Ok(Self {
            facts,
            sensors: of("sensors"),
            actions: of("actions"),
            plans: of("plans"),
            sensor_keys: keys("sensors"),
            action_keys: keys("actions"),
        })
    }
}

/// One of the generated enums: its variants, ids and names.
#[allow(clippy::too_many_arguments)] // One enum: its kind, types, names and the mission's.
fn names_enum(
    what: &str,
    ty: &Ident,
    id: Tokens,
    repr: Tokens,
    variants: &[Ident],
    names: &[&str],
    described: &[Option<String>],
    (mission, of): (&Ident, Tokens),
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
                Some(d) => format!("{name}: {}", doc_line(&d)),
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
        // A variant is the mission's name, not the user's code: one that starts with a letter
        // that has no upper case of one character (`ßx`) warns in no crate.
        #[allow(non_camel_case_types)]
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

        impl #of<#mission> for #ty {
            fn id(self) -> #id {
                Self::id(self)
            }
            fn from_id(id: #id) -> ::core::option::Option<Self> {
                Self::from_id(id)
            }
        }

        impl ::core::convert::From<#ty> for #id {
            fn from(name: #ty) -> #id {
                name.id()
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

/// The mission's type name: the module's name in UpperCamelCase (`fetch_tea` is `FetchTea`);
/// an error where it would clash with another item of the module.
fn mission_type(module: &Ident) -> syn::Result<Ident> {
    let name = variant(&module.to_string());
    const TAKEN: [&str; 17] = [
        "Sensor", "Action", "Fact", "Event", "Plan", "Run", "Io", "Runtime", "HASH", "W", "NF",
        "NS", "NA", "NP", "L", "K", "TABLES",
    ];
    if TAKEN.contains(&name.as_str()) {
        return Err(syn::Error::new(
            module.span(),
            format!(
                "the module `{module}` makes the mission's type `{name}`, a name the module \
                 already gives another item: rename the module"
            ),
        ));
    }
    syn::parse_str::<Ident>(&name)
        .map(|i| Ident::new(&i.to_string(), module.span()))
        .map_err(|_| {
            syn::Error::new(
                module.span(),
                format!("the module `{module}` makes no type name ({name}): rename it"),
            )
        })
}

/// `join` of the futures `items` (each an expression of a future that never ends), nested in
/// fours, as one expression.
fn join_tree(items: &[Tokens]) -> Tokens {
    match items {
        [] => quote!(::core::future::pending::<::core::convert::Infallible>()),
        [one] => one.clone(),
        _ if items.len() <= 4 => {
            let f = format_ident!("join{}", items.len());
            let f = if items.len() == 2 {
                format_ident!("join")
            } else {
                f
            };
            quote!(::psmpa_core::embassy_futures::join::#f(#(#items),*))
        }
        _ => {
            let chunk = items.len().div_ceil(4);
            let parts: Vec<Tokens> = items.chunks(chunk).map(join_tree).collect();
            join_tree(&parts)
        }
    }
}

fn generate(
    input: &Input,
    m: &Large<'_, MAX_WORDS, MAX_FACTS>,
    file: &Path,
    keys_option: Option<usize>,
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
    let module = &input.name;
    let mission = mission_type(module)?;

    let fact_v = variants("facts", fact_names, span)?;
    let event_v = variants("events", event_names, span)?;
    let sensor_v = variants("sensors", &sensor_names, span)?;
    let action_v = variants("actions", &action_names, span)?;
    let plan_v = variants("plans", &plan_names, span)?;

    // The declared keys, numbered across the mission from 1 (0 is a sensor's sample).
    let mut key_names: Vec<String> = Vec::new();
    for k in descriptions
        .sensor_keys
        .iter()
        .chain(&descriptions.action_keys)
        .flatten()
    {
        if !key_names.iter().any(|n| n == k) {
            key_names.push(k.clone());
        }
    }
    if key_names.len() > usize::from(u8::MAX) {
        return Err(syn::Error::new(
            span,
            format!(
                "the mission declares {} keys: at most 255 (a key is a u8, 0 the sample's)",
                key_names.len()
            ),
        ));
    }
    let key_refs: Vec<&str> = key_names.iter().map(String::as_str).collect();
    let key_v = variants("keys", &key_refs, span)?;
    let key_of = |name: &str| key_names.iter().position(|k| k == name);
    // `impl TRAIT for key::K` for each key behaviour `i` of `declared` declares.
    let key_impls = |declared: &[Vec<String>], i: usize, of: Tokens| -> Vec<Tokens> {
        let names = declared.get(i).into_iter().flatten();
        names
            .filter_map(|k| {
                let kv = key_v.get(key_of(k)?)?;
                Some(quote! {
                    impl #of for super::key::#kv {
                        fn key(self) -> ::psmpa_core::Key {
                            ::psmpa_core::Key::from(self)
                        }
                    }
                })
            })
            .collect()
    };
    // Keys a data store holds: a sensor's sample and its keys, an action's keys; or `keys = N`.
    let most = descriptions
        .sensor_keys
        .iter()
        .map(|k| k.len().saturating_add(1))
        .chain(descriptions.action_keys.iter().map(Vec::len))
        .max()
        .unwrap_or(0)
        .max(1);
    let k = keys_option.unwrap_or(most);
    if k < most {
        return Err(syn::Error::new(
            input.keys.as_ref().map_or(span, syn::LitInt::span),
            format!(
                "keys = {k}: a data store of the mission needs room for {most} keys (a \
                 sensor's sample and its declared keys, or an action's declared keys)"
            ),
        ));
    }

    let of = |t: &str| -> Tokens {
        let t = format_ident!("{t}");
        quote!(::psmpa_core::#t)
    };
    let enums = [
        names_enum(
            "fact",
            &format_ident!("Fact"),
            quote!(::psmpa_core::FactId),
            quote!(u16),
            &fact_v,
            fact_names,
            &descriptions.facts,
            (&mission, of("FactOf")),
        ),
        names_enum(
            "event",
            &format_ident!("Event"),
            quote!(::psmpa_core::EventId),
            quote!(u8),
            &event_v,
            event_names,
            &[],
            (&mission, of("EventOf")),
        ),
        names_enum(
            "sensor",
            &format_ident!("Sensor"),
            quote!(::psmpa_core::SensorId),
            quote!(u8),
            &sensor_v,
            &sensor_names,
            &descriptions.sensors,
            (&mission, of("SensorOf")),
        ),
        names_enum(
            "action",
            &format_ident!("Action"),
            quote!(::psmpa_core::ActionId),
            quote!(u16),
            &action_v,
            &action_names,
            &descriptions.actions,
            (&mission, of("ActionOf")),
        ),
        names_enum(
            "plan",
            &format_ident!("Plan"),
            quote!(::psmpa_core::PlanId),
            quote!(u8),
            &plan_v,
            &plan_names,
            &descriptions.plans,
            (&mission, of("PlanOf")),
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

    let mode_of = |mode: SensorMode| match mode {
        SensorMode::Cyclic { period } => {
            let ms = millis(period);
            quote!(::psmpa_core::SensorMode::Cyclic { period: ::psmpa_core::embassy_time::Duration::from_millis(#ms) })
        }
        SensorMode::OneShot => quote!(::psmpa_core::SensorMode::OneShot),
        SensorMode::OnDemand => quote!(::psmpa_core::SensorMode::OnDemand),
    };
    let max_violation_of = |t: Option<embassy_time::Duration>| match t {
        Some(t) => {
            let ms = millis(t);
            quote!(::core::option::Option::Some(::psmpa_core::embassy_time::Duration::from_millis(#ms)))
        }
        None => quote!(::core::option::Option::None),
    };
    let sensors = d.sensors().iter().map(|s| {
        let (name, pre, per) = (s.name, facts(s.pre, w), facts(s.per, w));
        let mode = mode_of(s.mode);
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
        let max_violation = max_violation_of(a.max_violation);
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

    // One type a sensor: its name for `ActionIo::sample`, and its sampler's constants.
    let sensor_types = d.sensors().iter().enumerate().map(|(i, s)| {
        let v = &sensor_v[i];
        let doc = format!(
            "The sensor `{}`, as a type: its sampler's constants.",
            s.name.replace('`', "'")
        );
        let mode = mode_of(s.mode);
        let timeout = millis(s.timeout);
        let per = facts(s.per, w);
        let keys = key_impls(
            &descriptions.sensor_keys,
            i,
            quote!(::psmpa_core::KeyOf<#v>),
        );
        quote! {
            #[doc = #doc]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
            pub struct #v;

            impl ::psmpa_core::SensorOf<super::#mission> for #v {
                fn id(self) -> ::psmpa_core::SensorId {
                    ::psmpa_core::SensorId::of::<#i>()
                }
                fn from_id(id: ::psmpa_core::SensorId) -> ::core::option::Option<Self> {
                    (id.index() == #i).then_some(Self)
                }
            }

            impl ::psmpa_core::spec::SensorSpec<super::#mission> for #v {
                #[inline(always)]
                fn id(self) -> ::psmpa_core::SensorId {
                    ::psmpa_core::SensorId::of::<#i>()
                }
                #[inline(always)]
                fn sensor(self) -> super::Sensor {
                    super::Sensor::#v
                }
                #[inline(always)]
                fn mode(self) -> ::psmpa_core::SensorMode {
                    #mode
                }
                #[inline(always)]
                fn timeout(self) -> ::psmpa_core::embassy_time::Duration {
                    ::psmpa_core::embassy_time::Duration::from_millis(#timeout)
                }
                #[inline(always)]
                fn per(self) -> ::psmpa_core::FactSetOf<#w> {
                    #per
                }
            }

            #(#keys)*
        }
    });

    // One type an action, with the sensors Algorithm 2 runs beside it and its own keys.
    let action_types = d.actions().iter().enumerate().map(|(i, a)| {
        let v = &action_v[i];
        let serving = d.sensors_serving(a.pre);
        let beside = serving.iter().map(|s| {
            let sv = &sensor_v[s.index()];
            quote!(impl ::psmpa_core::Beside<super::sensor::#sv> for #v {})
        });
        let names: Vec<String> = serving
            .iter()
            .map(|s| format!("`{}`", sensor_names[s.index()].replace('`', "'")))
            .collect();
        let doc = format!(
            "The action `{}`, as a type: its I/O reads {}.",
            a.name.replace('`', "'"),
            if names.is_empty() {
                "no sensor".to_owned()
            } else {
                format!("the sensors {}", names.join(", "))
            }
        );
        let keys = key_impls(
            &descriptions.action_keys,
            i,
            quote!(::psmpa_core::OwnKey<#v>),
        );
        quote! {
            #[doc = #doc]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
            pub struct #v;
            #(#beside)*
            impl ::psmpa_core::Beside<::psmpa_core::spec::io::Nowhere> for #v {}
            #(#keys)*
        }
    });

    let key_types = key_v.iter().enumerate().map(|(i, v)| {
        let n = u8::try_from(i + 1).unwrap_or(u8::MAX);
        let doc = format!(
            "The key `{}` of a data store (key {n}).",
            key_names[i].replace('`', "'")
        );
        quote! {
            #[doc = #doc]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
            pub struct #v;

            impl ::core::convert::From<#v> for ::psmpa_core::Key {
                fn from(_: #v) -> ::psmpa_core::Key {
                    ::psmpa_core::Key(#n)
                }
            }
        }
    });

    let run_variants = action_v.iter().zip(&action_names).map(|(v, name)| {
        let doc = format!("Run `{}` with its I/O.", name.replace('`', "'"));
        quote!(#[doc = #doc] #v(Io<'io, action::#v>))
    });
    // An enum of no action still uses its lifetime.
    let never_variant = action_v.is_empty().then(|| {
        quote! {
            #[doc(hidden)]
            __Never(::core::convert::Infallible, ::core::marker::PhantomData<&'io ()>),
        }
    });
    let typed_arms = action_v
        .iter()
        .map(|v| quote!(Action::#v => Run::#v(io.__as())));
    let typed_body = if action_v.is_empty() {
        quote!(match io.action() {})
    } else {
        quote!(match io.action() { #(#typed_arms,)* })
    };

    // Algorithm 2 at build time: each plan's states, constants (a state per action of its body,
    // the sensors that serve its precondition, its effects).
    let mut state_types = Vec::new();
    let mut plan_arms = Vec::new();
    for (pi, p) in plans.iter().enumerate() {
        let ty = format_ident!("P{pi}");
        let n = p.body.len();
        let states = p.body.iter().enumerate().filter_map(|(si, a)| {
            let spec = d.action(*a)?;
            let av = &action_v[a.index()];
            let sensors = d.sensors_serving(spec.pre).bits();
            let (pre, add, del) = (facts(spec.pre, w), facts(spec.add, w), facts(spec.del, w));
            let max_violation = max_violation_of(spec.max_violation);
            let index = u8::try_from(si).unwrap_or(u8::MAX);
            Some(quote! {
                ::psmpa_core::spec::State {
                    index: #index,
                    action: super::Action::#av,
                    sensors: ::psmpa_core::SensorSet::from_bits(#sensors),
                    pre: #pre,
                    add: #add,
                    del: #del,
                    max_violation: #max_violation,
                }
            })
        });
        let doc = format!(
            "The states of plan `{}`, Algorithm 2 at build time.",
            p.name.replace('`', "'")
        );
        state_types.push(quote! {
            #[doc = #doc]
            pub const #ty: [::psmpa_core::spec::State<super::#mission>; #n] = [#(#states),*];
        });
        plan_arms.push(quote!(#pi => ::core::option::Option::Some(&__states::#ty)));
    }

    let samplers: Vec<Tokens> = sensor_v
        .iter()
        .map(|v| quote!(sensing.sampler(sensor::#v)))
        .collect();
    let joined = join_tree(&samplers);

    let vis = &input.vis;
    let file = file.to_string_lossy().into_owned();
    let doc = format!(
        "The mission `{}` of `{}`, compiled in: its type [`{mission}`], its names as enums and \
         types, its plans' states as constants and a sampler per sensor ({nf} facts, {} events, {ns} sensors, \
         {na} actions, {np} plans).",
        mission_name.replace('`', "'"),
        input.path.value(),
        event_names.len()
    );
    let mission_doc = format!(
        "The mission `{}` as a type: `Runtime::new({mission}, &robot, sink, config)`. A \
         platform for it implements `Sensor<{mission}>` and `Actuator<{mission}>`.",
        mission_name.replace('`', "'")
    );
    let attrs = &input.attrs;
    let np_lit = np;
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
            pub const K: usize = #k;

            #(#tick_checks)*

            #(#enums)*

            #[doc = #mission_doc]
            #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
            pub struct #mission;

            /// The runtime of platform `P` for this mission, tracing into `T`:
            #[doc = concat!("`Runtime::new(", stringify!(#mission), ", &robot, (), config)`.")]
            pub type Runtime<'r, P, T = ()> = ::psmpa_core::Runtime<'r, #mission, P, T>;

            /// The I/O of action `A` (one of [`action`]'s types): it reads the sensors that
            /// run beside `A`, and their keys and `A`'s.
            pub type Io<'io, A> = ::psmpa_core::ActionIo<'io, #mission, A>;

            /// An action to run with its typed I/O: `match act.typed() { .. }` in
            /// `Actuator::run`.
            pub enum Run<'io> {
                #(#run_variants,)*
                #never_variant
            }

            /// The mission's sensors as types: what an action's I/O reads
            /// (`io.sample(sensor::Sonar)`).
            pub mod sensor {
                #(#sensor_types)*
            }

            /// The mission's actions as types: each says which sensors run beside it
            /// (`psmpa_core::Beside`) and which keys its own data store has.
            pub mod action {
                #(#action_types)*
            }

            /// The keys the mission declares for its data stores (`"keys"` of a sensor or an
            /// action).
            pub mod key {
                #(#key_types)*
            }

            #[doc(hidden)]
            pub mod __states {
                #(#state_types)*
            }

            /// The mission's tables, built at compile time from the file and checked there:
            /// what tools read (names, modes, plans). The runtime is made from
            #[doc = concat!("[`", stringify!(#mission), "`].")]
            pub static TABLES: ::psmpa_core::Tables<'static, NS, NA, NP, L, #w, NF> = ::psmpa_core::Tables {
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

            impl ::psmpa_core::Mission for #mission {
                type Facts = ::psmpa_core::FactSetOf<#w>;
                type Sensor = Sensor;
                type Action = Action;
                type Plan = Plan;
                type Fact = Fact;
                type Event = Event;
                type Storage<Mx: ::psmpa_core::embassy_sync::blocking_mutex::raw::RawMutex> =
                    ::psmpa_core::spec::Store<Mx, #ns, #na, #k, #w>;
                type Run<'io> = Run<'io> where Self: 'io;
                type Body = ::psmpa_core::__heapless::Vec<::psmpa_core::ActionId, #l>;
                type Actions<'a> = ::psmpa_core::__heapless::Vec<::psmpa_core::ActuatorAction<'a, #w>, #na> where Self: 'a;

                fn name(&self) -> &str {
                    #mission_name
                }
                fn fact_names(&self) -> &[&str] {
                    TABLES.domain.fact_names()
                }
                fn event_names(&self) -> &[&str] {
                    TABLES.domain.event_names()
                }
                fn sensors(&self) -> &[::psmpa_core::SensorAction<'_, #w>] {
                    TABLES.domain.sensors()
                }
                fn actions(&self) -> &[::psmpa_core::ActuatorAction<'_, #w>] {
                    TABLES.domain.actions()
                }
                fn plan_count(&self) -> usize {
                    #np_lit
                }
                fn plan(
                    &self,
                    id: ::psmpa_core::PlanId,
                ) -> ::core::option::Option<::psmpa_core::spec::PlanRef<'_, ::psmpa_core::FactSetOf<#w>>> {
                    TABLES.library.get(id).map(::psmpa_core::spec::PlanRef::from)
                }
                fn task(&self) -> ::psmpa_core::Task<#w> {
                    TABLES.task
                }
                fn typed(io: ::psmpa_core::ActionIo<'_, Self, ::psmpa_core::Untyped>) -> Run<'_> {
                    #typed_body
                }
                fn states(
                    &self,
                    plan: ::psmpa_core::PlanId,
                ) -> ::core::option::Option<&[::psmpa_core::spec::State<Self>]> {
                    match plan.index() {
                        #(#plan_arms,)*
                        _ => ::core::option::Option::None,
                    }
                }
                fn sensing<E: ::psmpa_core::spec::Sensing<Mission = Self>>(
                    &self,
                    sensing: &E,
                ) -> impl ::core::future::Future<Output = ::core::convert::Infallible> {
                    // Built here, not in the first poll.
                    ::psmpa_core::spec::Samplers::new(#joined)
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_description_never_makes_a_code_block_and_a_variant_never_warns() {
        let fenced = "Near the door.\n```\npanic!()\n```\n\n    indented();\n";
        let line = doc_line(fenced);
        assert_eq!(line, "Near the door. ''' panic!() ''' indented();");
        let ty = format_ident!("Fact");
        let tokens = names_enum(
            "fact",
            &ty,
            quote!(FactId),
            quote!(u8),
            &[format_ident!("Near")],
            &["near"],
            &[Some(fenced.to_owned())],
            (&format_ident!("M"), quote!(())),
        )
        .to_string();
        let docs: Vec<&str> = tokens.split("doc = ").skip(1).collect();
        assert!(
            docs.iter()
                .any(|d| d.starts_with("\"`near`: Near the door.")),
            "{tokens}"
        );
        assert!(
            docs.iter()
                .all(|d| !d.starts_with("\"`near`: Near the door.\\n")),
            "{tokens}"
        );
        assert!(tokens.contains("allow (non_camel_case_types)"), "{tokens}");
    }

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
