//! Algorithm 3, the mutual data store mechanism.
//!
//! Every behaviour (sensor-based or actuator-based action) owns a [`DataStore`] `d_i(k, v)`:
//! a fixed-capacity map from small integer [`Key`]s to typed [`Value`]s stamped with the
//! [`Instant`] they describe. A sample puts its value under [`SAMPLE_KEY`] and any further
//! `(k', v')` pairs the sensor gives ([`Reading::put`](crate::platform::Reading::put)) into
//! its sensor's store (line 6). While a sensor `s_j` runs beside an action `a_i`
//! (`per(s_j) ⊆ pre(a_i)`), the [`MutualStore`] `d_mutual(s_j, a_i)` joins their stores: the
//! action reads any key of any of its sensors, by sensor, with no I/O in between (lines 7-8).
//!
//! Stores are generic over an `embassy_sync` [`RawMutex`] so the same code is sound between
//! interrupt priorities on a microcontroller and between test threads on a host. A full store
//! returns [`StoreFull`] with the value handed back; nothing is dropped silently.
//!
//! Cost: `get` and `put` hash the key to `key mod K` and probe linearly, so keys `0..K` never
//! collide and cost one probe; the worst case is `K` probes. No allocation, no panic.

use core::cell::Cell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::Instant;

use crate::action::{SensorId, SensorSet};

/// Key of a value in a data store.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Key(pub u8);

/// The key under which the runtime stores a sensor's latest sample in that sensor's store.
pub const SAMPLE_KEY: Key = Key(0);

/// A typed value: what sensors measure and behaviours exchange. Integer units only, so that
/// every platform computes the same thing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Value {
    /// A yes/no reading (the camera sees the door handle).
    Bool(bool),
    /// A signed integer in the sensor's own unit (an encoder count, a temperature in m°C, an
    /// acceleration in mm/s²).
    Int(i32),
    /// A signed distance in millimetres: a range, a position, an offset from a line.
    Mm(i32),
    /// A discrete level (bumper: 0 off, 1 no contact, 2 contact).
    Level(u8),
    /// A ranging sensor answered and nothing lay within its range (no echo came back). Not a
    /// distance: a behaviour must not mistake it for "very far" or for 0.
    NoEcho,
}

/// A stored value and the time it was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Entry {
    /// The value.
    pub value: Value,
    /// When it was written.
    pub at: Instant,
}

/// A `put` of a new key into a full store: the key and value are handed back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StoreFull {
    /// The key that found no room.
    pub key: Key,
    /// The value that was not stored.
    pub value: Value,
    /// The store's capacity.
    pub capacity: usize,
}

impl core::fmt::Display for StoreFull {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "a data store of {} keys is full: no room for key {}",
            self.capacity, self.key.0
        )
    }
}

impl core::error::Error for StoreFull {}

/// Read and write access to one data store, whatever its capacity and mutex.
///
/// Object safe, so behaviours see every store through the same `&dyn StoreAccess`.
pub trait StoreAccess {
    /// The latest entry under `key`. O(1) for `key < capacity`, O(capacity) worst case.
    fn get(&self, key: Key) -> Option<Entry>;
    /// Stores `value` under `key`, replacing the previous value of that key. A new key in a
    /// full store is an `Err` that hands the value back. Same cost as [`get`](Self::get).
    fn put(&self, key: Key, value: Value, at: Instant) -> Result<(), StoreFull>;
    /// Number of keys stored.
    fn len(&self) -> usize;
    /// Whether no key is stored.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Most keys the store can hold.
    fn capacity(&self) -> usize;
    /// Number of successful `put`s so far (wraps), to tell whether something new arrived.
    fn version(&self) -> u32;
}

type Slot = Cell<Option<(Key, Entry)>>;

struct Slots<const K: usize> {
    slots: [Slot; K],
    len: Cell<usize>,
    version: Cell<u32>,
}

/// A behaviour's data store `d_i(k, v)` with room for `K` keys.
pub struct DataStore<M: RawMutex, const K: usize> {
    inner: Mutex<M, Slots<K>>,
}

impl<M: RawMutex, const K: usize> Default for DataStore<M, K> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: RawMutex, const K: usize> DataStore<M, K> {
    /// An empty store; usable in a `static`.
    pub const fn new() -> Self {
        Self {
            inner: Mutex::new(Slots {
                slots: [const { Cell::new(None) }; K],
                len: Cell::new(0),
                version: Cell::new(0),
            }),
        }
    }

    /// Removes every key.
    pub fn clear(&self) {
        self.inner.lock(|s| {
            for slot in &s.slots {
                slot.set(None);
            }
            s.len.set(0);
        });
    }

    /// The slot index where `key` is, or where it would go, or `None` when the store is full
    /// and does not hold `key`.
    fn find(slots: &Slots<K>, key: Key) -> Option<(usize, bool)> {
        let start = usize::from(key.0).checked_rem(K)?;
        // Keys below `K` sit in their own slot: one look.
        match slots.slots.get(start)?.get() {
            Some((k, _)) if k == key => Some((start, true)),
            None => Some((start, false)),
            Some(_) => Self::probe(slots, key, start),
        }
    }

    /// [`find`](Self::find) past a collision: linear probing. O(K).
    #[inline(never)]
    fn probe(slots: &Slots<K>, key: Key, start: usize) -> Option<(usize, bool)> {
        for probe in 1..K {
            let index = start.wrapping_add(probe).checked_rem(K)?;
            match slots.slots.get(index).map(Cell::get) {
                Some(Some((k, _))) if k == key => return Some((index, true)),
                Some(None) => return Some((index, false)),
                _ => {}
            }
        }
        None
    }
}

impl<M: RawMutex, const K: usize> StoreAccess for DataStore<M, K> {
    fn get(&self, key: Key) -> Option<Entry> {
        self.inner.lock(|s| match Self::find(s, key) {
            Some((index, true)) => s.slots.get(index)?.get().map(|(_, e)| e),
            _ => None,
        })
    }

    fn put(&self, key: Key, value: Value, at: Instant) -> Result<(), StoreFull> {
        let full = || StoreFull {
            key,
            value,
            capacity: K,
        };
        self.inner.lock(|s| {
            let (index, existed) = Self::find(s, key).ok_or_else(full)?;
            let slot = s.slots.get(index).ok_or_else(full)?;
            slot.set(Some((key, Entry { value, at })));
            if !existed {
                s.len.set(s.len.get().saturating_add(1));
            }
            s.version.set(s.version.get().wrapping_add(1));
            Ok(())
        })
    }

    fn len(&self) -> usize {
        self.inner.lock(|s| s.len.get())
    }

    fn capacity(&self) -> usize {
        K
    }

    fn version(&self) -> u32 {
        self.inner.lock(|s| s.version.get())
    }
}

/// The stores of a domain's sensor-based actions, indexed by [`SensorId`].
pub trait SensorStores {
    /// The store of sensor `sensor`.
    fn store(&self, sensor: SensorId) -> Option<&dyn StoreAccess>;

    /// `get(key)` on the store of sensor `sensor`: one call where a behaviour reads a sample.
    fn get(&self, sensor: SensorId, key: Key) -> Option<Entry> {
        self.store(sensor)?.get(key)
    }
}

impl<M: RawMutex, const K: usize, const N: usize> SensorStores for [DataStore<M, K>; N] {
    fn store(&self, sensor: SensorId) -> Option<&dyn StoreAccess> {
        <[_]>::get(self, sensor.index()).map(|s| s as &dyn StoreAccess)
    }

    fn get(&self, sensor: SensorId, key: Key) -> Option<Entry> {
        <[_]>::get(self, sensor.index())?.get(key)
    }
}

/// The mutual data store `d_mutual(s_j, a_i)` of Algorithm 3: an actuator-based action's own
/// store joined with the stores of the sensors running beside it.
#[derive(Clone, Copy)]
pub struct MutualStore<'s> {
    own: &'s dyn StoreAccess,
    sensors: &'s dyn SensorStores,
    linked: SensorSet,
}

impl<'s> MutualStore<'s> {
    /// `setDataStore(d_sj, d_ai)` for every sensor `s_j` in `linked` (line 7).
    pub fn link(
        own: &'s dyn StoreAccess,
        sensors: &'s dyn SensorStores,
        linked: SensorSet,
    ) -> Self {
        Self {
            own,
            sensors,
            linked,
        }
    }

    /// The sensors whose stores are joined.
    pub fn linked(&self) -> SensorSet {
        self.linked
    }

    /// `a_i.get(d_mutual(s_j, a_i), k')` (line 8): what linked sensor `s_j` put under `key`;
    /// `None` for a sensor that is not running beside the action. Two sensors may use the same
    /// key for different things, so a read always names the sensor. A key stays until the
    /// sensor puts it again: its entry's instant says which sample it came from. One store
    /// lookup.
    pub fn get(&self, sensor: SensorId, key: Key) -> Option<Entry> {
        if !self.linked.contains(sensor) {
            return None;
        }
        self.sensors.get(sensor, key)
    }

    /// The latest sample of a linked sensor: its value under [`SAMPLE_KEY`].
    pub fn sample(&self, sensor: SensorId) -> Option<Entry> {
        self.get(sensor, SAMPLE_KEY)
    }

    /// The action's own value for `key` (`d_{a_i}`, line 2).
    pub fn own(&self, key: Key) -> Option<Entry> {
        self.own.get(key)
    }

    /// Writes into the action's own store.
    pub fn put(&self, key: Key, value: Value, at: Instant) -> Result<(), StoreFull> {
        self.own.put(key, value, at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_sync::blocking_mutex::raw::NoopRawMutex;

    fn t(ms: u64) -> Instant {
        Instant::from_millis(ms)
    }

    #[test]
    fn full_store_hands_the_value_back_and_keeps_what_it_had() {
        let store: DataStore<NoopRawMutex, 2> = DataStore::new();
        store.put(Key(7), Value::Int(1), t(1)).unwrap();
        store.put(Key(9), Value::Int(2), t(2)).unwrap();
        let err = store.put(Key(11), Value::Int(3), t(3)).unwrap_err();
        assert_eq!(
            err,
            StoreFull {
                key: Key(11),
                value: Value::Int(3),
                capacity: 2
            }
        );
        // Replacing an existing key still works when full.
        store.put(Key(9), Value::Int(4), t(4)).unwrap();
        assert_eq!(store.get(Key(7)).unwrap().value, Value::Int(1));
        assert_eq!(
            store.get(Key(9)),
            Some(Entry {
                value: Value::Int(4),
                at: t(4)
            })
        );
        assert_eq!(store.get(Key(11)), None);
        assert_eq!(store.len(), 2);
        assert_eq!(store.version(), 3);
    }

    #[test]
    fn colliding_keys_probe_to_free_slots() {
        let store: DataStore<NoopRawMutex, 4> = DataStore::new();
        for (i, k) in [1u8, 5, 9, 13].into_iter().enumerate() {
            store.put(Key(k), Value::Int(i as i32), t(0)).unwrap();
        }
        for (i, k) in [1u8, 5, 9, 13].into_iter().enumerate() {
            assert_eq!(store.get(Key(k)).unwrap().value, Value::Int(i as i32));
        }
        assert!(store.put(Key(2), Value::Bool(true), t(0)).is_err());
        store.clear();
        assert!(store.is_empty());
        assert_eq!(store.get(Key(1)), None);
    }

    #[test]
    fn zero_capacity_store_rejects_everything_without_panicking() {
        let store: DataStore<NoopRawMutex, 0> = DataStore::new();
        assert!(store.put(Key(0), Value::Bool(true), t(0)).is_err());
        assert_eq!(store.get(Key(0)), None);
    }

    #[test]
    fn mutual_store_reads_own_then_linked_sensors() {
        let own: DataStore<NoopRawMutex, 4> = DataStore::new();
        let sensors: [DataStore<NoopRawMutex, 4>; 3] = [const { DataStore::new() }; 3];
        let s0 = SensorId::new(0).unwrap();
        let s1 = SensorId::new(1).unwrap();
        let s2 = SensorId::new(2).unwrap();
        sensors[0].put(SAMPLE_KEY, Value::Mm(450), t(5)).unwrap();
        sensors[1].put(SAMPLE_KEY, Value::Level(2), t(6)).unwrap();
        sensors[2].put(SAMPLE_KEY, Value::NoEcho, t(7)).unwrap();
        // The same key in two sensors' stores means two things: reads name the sensor.
        sensors[1].put(Key(3), Value::Int(-40), t(6)).unwrap();
        sensors[2].put(Key(3), Value::Bool(true), t(7)).unwrap();
        let mutual = MutualStore::link(&own, &sensors, SensorSet::EMPTY.with(s1).with(s2));
        // s0 is not beside this action: its store is not reachable.
        assert_eq!(mutual.sample(s0), None);
        assert_eq!(mutual.get(s0, SAMPLE_KEY), None);
        assert_eq!(mutual.sample(s1).unwrap().value, Value::Level(2));
        assert_eq!(mutual.sample(s2).unwrap().value, Value::NoEcho);
        assert_eq!(mutual.get(s1, Key(3)).unwrap().value, Value::Int(-40));
        assert_eq!(mutual.get(s2, Key(3)).unwrap().at, t(7));
        // The action's own store is separate from every sensor's.
        assert_eq!(mutual.own(Key(3)), None);
        mutual.put(Key(3), Value::Mm(-12), t(8)).unwrap();
        assert_eq!(mutual.own(Key(3)).unwrap().value, Value::Mm(-12));
        assert_eq!(mutual.get(s2, Key(3)).unwrap().value, Value::Bool(true));
    }
}
