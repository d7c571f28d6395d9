//! Chunk, index and header checksums: XXH3-64 (seed 0), stored little-endian.

pub fn xxh3(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}
