//! SplitMix64, the tasks' one seeded generator (the bench's switch bounces and unshipped
//! scenarios, the static timing's call arguments): the same draws on every machine.

/// The next word after `state`, which it advances.
pub fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
