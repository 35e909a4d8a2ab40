//! Data-store get + put: psmpa's `DataStore` against a fixed array indexed by key (the floor),
//! `heapless::FnvIndexMap` and `std::collections::HashMap<String, _>`. One element is one
//! get followed by one put of the same key; every iteration touches the 8 keys in turn.

use std::collections::HashMap;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::Instant;
use psmpa_core::{DataStore, Key, StoreAccess, Value};

const KEYS: u8 = 8;

fn bump(v: Value) -> Value {
    match v {
        Value::Int(i) => Value::Int(i.wrapping_add(1)),
        other => other,
    }
}

fn store(c: &mut Criterion) {
    let at = Instant::from_ticks(1);
    let mut group = c.benchmark_group("store");
    group.throughput(Throughput::Elements(u64::from(KEYS)));

    let mut array: [Option<(Value, Instant)>; KEYS as usize] =
        [Some((Value::Int(0), at)); KEYS as usize];
    group.bench_function("fixed array", |b| {
        b.iter(|| {
            for k in 0..KEYS {
                let k = usize::from(black_box(k));
                let v = array[k].map_or(Value::Int(0), |(v, _)| v);
                array[k] = Some((bump(v), at));
            }
        })
    });

    let psmpa: DataStore<NoopRawMutex, { KEYS as usize }> = DataStore::new();
    for k in 0..KEYS {
        psmpa
            .put(Key(k), Value::Int(0), at)
            .expect("room for 8 keys");
    }
    group.bench_function("psmpa DataStore", |b| {
        b.iter(|| {
            for k in 0..KEYS {
                let k = Key(black_box(k));
                let v = psmpa.get(k).map_or(Value::Int(0), |e| e.value);
                psmpa.put(k, bump(v), at).expect("an existing key");
            }
        })
    });

    let mut fnv: heapless::index_map::FnvIndexMap<u8, (Value, Instant), { KEYS as usize }> =
        heapless::index_map::FnvIndexMap::new();
    for k in 0..KEYS {
        fnv.insert(k, (Value::Int(0), at)).expect("room for 8 keys");
    }
    group.bench_function("heapless FnvIndexMap", |b| {
        b.iter(|| {
            for k in 0..KEYS {
                let k = black_box(k);
                let v = fnv.get(&k).map_or(Value::Int(0), |(v, _)| *v);
                fnv.insert(k, (bump(v), at)).expect("an existing key");
            }
        })
    });

    let names: Vec<String> = (0..KEYS).map(|k| format!("key{k}")).collect();
    let mut map: HashMap<String, (Value, Instant)> = HashMap::new();
    for name in &names {
        map.insert(name.clone(), (Value::Int(0), at));
    }
    group.bench_function("std HashMap<String, _>", |b| {
        b.iter(|| {
            for name in &names {
                let name = black_box(name.as_str());
                let v = map.get(name).map_or(Value::Int(0), |(v, _)| *v);
                match map.get_mut(name) {
                    Some(slot) => *slot = (bump(v), at),
                    None => {
                        map.insert(name.to_owned(), (bump(v), at));
                    }
                }
            }
        })
    });
    group.finish();
}

criterion_group!(benches, store);
criterion_main!(benches);
