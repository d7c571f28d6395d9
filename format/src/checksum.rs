//! Chunk, index and header checksums: XXH3-64 (seed 0), stored little-endian.

/// XXH3-64 of `bytes` with seed 0: every checksum in a `.vbim` file.
pub fn xxh3(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}
