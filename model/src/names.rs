//! Names instead of indices: fact sets printed with a domain's names.
//!
//! ```
//! # use psmpa_model::{Domain, FactSet};
//! let mut d: Domain<'_, 1, 1> = Domain::new();
//! let clear = d.add_fact("path_clear").unwrap();
//! let door = d.add_fact("at_door").unwrap();
//! let set = FactSet::single(clear).with(door);
//! assert_eq!(format!("{}", d.names(set)), "{path_clear, at_door}");
//! ```

use core::fmt;

use crate::domain::Domain;
use crate::facts::FactSetOf;

/// A fact set printed with its facts' names ([`Domain::names`]); `Debug` prints the same, and
/// so does `defmt::Format` (feature `defmt`).
#[derive(Clone, Copy)]
pub struct FactNames<
    'd,
    'a,
    const NS: usize,
    const NA: usize,
    const W: usize = 1,
    const NF: usize = 64,
> {
    domain: &'d Domain<'a, NS, NA, W, NF>,
    set: FactSetOf<W>,
}

impl<'a, const NS: usize, const NA: usize, const W: usize, const NF: usize>
    Domain<'a, NS, NA, W, NF>
{
    /// `set` with the names of its facts: `{path_clear, at_door}`. A fact the domain does not
    /// declare prints as its index.
    pub fn names(&self, set: FactSetOf<W>) -> FactNames<'_, 'a, NS, NA, W, NF> {
        FactNames { domain: self, set }
    }
}

impl<const NS: usize, const NA: usize, const W: usize, const NF: usize> fmt::Display
    for FactNames<'_, '_, NS, NA, W, NF>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("{")?;
        for (i, fact) in self.set.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            match self.domain.fact_name(fact) {
                Some(name) => f.write_str(name)?,
                None => write!(f, "#{}", fact.index())?,
            }
        }
        f.write_str("}")
    }
}

impl<const NS: usize, const NA: usize, const W: usize, const NF: usize> fmt::Debug
    for FactNames<'_, '_, NS, NA, W, NF>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// The same text in a defmt log, with no `core::fmt`: each name goes out as a string the host
/// prints (`info!("missing {}", domain.names(set))`).
#[cfg(feature = "defmt")]
impl<const NS: usize, const NA: usize, const W: usize, const NF: usize> defmt::Format
    for FactNames<'_, '_, NS, NA, W, NF>
{
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "{{");
        for (i, fact) in self.set.iter().enumerate() {
            if i > 0 {
                defmt::write!(f, ", ");
            }
            match self.domain.fact_name(fact) {
                Some(name) => defmt::write!(f, "{=str}", name),
                None => defmt::write!(f, "#{=usize}", fact.index()),
            }
        }
        defmt::write!(f, "}}");
    }
}
