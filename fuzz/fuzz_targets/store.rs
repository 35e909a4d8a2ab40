//! Any sequence of operations on a data store: an accepted value is readable until its key is
//! written again, a refused put changes nothing and only happens when the store is full.
#![no_main]

use std::collections::HashMap;

use arbitrary::Arbitrary;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::Instant;
use libfuzzer_sys::fuzz_target;
use psmpa_core::{DataStore, Key, StoreAccess, Value};

#[derive(Arbitrary, Debug)]
enum Op {
    Put(u8, i32),
    Get(u8),
    Clear,
}

fuzz_target!(|ops: Vec<Op>| {
    let store: DataStore<NoopRawMutex, 8> = DataStore::new();
    let mut model: HashMap<u8, i32> = HashMap::new();
    for (t, op) in ops.into_iter().enumerate() {
        match op {
            Op::Put(k, v) => match store.put(Key(k), Value::Int(v), Instant::from_ticks(t as u64)) {
                Ok(()) => {
                    model.insert(k, v);
                }
                Err(full) => {
                    assert_eq!(model.len(), 8);
                    assert!(!model.contains_key(&k));
                    assert_eq!(full.value, Value::Int(v));
                }
            },
            Op::Get(k) => assert_eq!(store.get(Key(k)).map(|e| e.value), model.get(&k).map(|v| Value::Int(*v))),
            Op::Clear => {
                store.clear();
                model.clear();
            }
        }
        assert_eq!(store.len(), model.len());
    }
});
