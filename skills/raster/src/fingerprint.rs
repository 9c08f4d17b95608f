//! Fast 64-bit fingerprints of bytes, for telling in-process copies of a layer apart: caches
//! that robots of one process share (cost planes, planner rasters, goal candidates) are found
//! by what they were built from. Not cryptographic and not stable between builds: never store
//! one. Two fingerprints of the same bytes with different seeds are independent, so a cache
//! that must not confuse two maps compares both.

/// The fingerprint of `bytes` under `seed`: four lanes of 8-byte words (so the multiplies
/// overlap), folded, then the bytes that do not fill a 32-byte block.
pub fn fingerprint(bytes: &[u8], seed: u64) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut lanes = [K, K.rotate_left(16), K.rotate_left(32), K.rotate_left(48)].map(|l| l ^ seed ^ bytes.len() as u64);
    let mut blocks = bytes.chunks_exact(32);
    for block in &mut blocks {
        for (lane, word) in lanes.iter_mut().zip(block.chunks_exact(8)) {
            let mut w = [0u8; 8];
            w.copy_from_slice(word);
            *lane = (*lane ^ u64::from_le_bytes(w)).wrapping_mul(K).rotate_left(31);
        }
    }
    let mut h = lanes.iter().fold(seed, |acc, &l| (acc ^ l).wrapping_mul(K).rotate_left(27));
    for &b in blocks.remainder() {
        h = (h ^ b as u64).wrapping_mul(K).rotate_left(5);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_and_the_length_and_the_seed_count() {
        let base: Vec<u8> = (0..203u32).map(|i| (i * 37 % 251) as u8).collect();
        let h = fingerprint(&base, 0);
        assert_eq!(h, fingerprint(&base.clone(), 0), "same bytes, same fingerprint");
        for i in 0..base.len() {
            let mut changed = base.clone();
            changed[i] ^= 1;
            assert_ne!(fingerprint(&changed, 0), h, "byte {i} (block or remainder) counts");
        }
        assert_ne!(fingerprint(&base[..202], 0), h, "length counts");
        let mut zero_padded = base.clone();
        zero_padded.push(0);
        assert_ne!(fingerprint(&zero_padded, 0), h, "a trailing zero counts");
        assert_ne!(fingerprint(&base, 1), h, "seed counts");
    }
}
