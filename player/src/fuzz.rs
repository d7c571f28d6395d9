//! The decoder thread's work on hostile bytes, for the fuzz target `player_decoder`
//! (`fuzz/`) and the test that replays what it kept: what a game's player does with a file
//! before anything reaches the GPU — every chunk verified and parsed, every segment that
//! becomes ready filled into a box of scanned streams.

use std::io::Cursor;

use vbim_format::{Limits, Reader};

use crate::decoder::{DecoderCore, Event, SegmentData};

/// What the target lets a file make the player hold (its own check, with no ring).
const LIMITS: Limits = Limits { memory: 64 << 20 };

/// Arbitrary bytes as a file (checksums made right, as `vbim_format::fuzz` does), taken
/// chunk by chunk in file order by the player's decoder, each ready segment packed: it
/// must return, whatever the bytes.
pub fn decoder(data: &[u8]) {
    let data = vbim_format::fuzz::with_checksums(data);
    let Ok(mut r) = Reader::open(Cursor::new(&data)) else {
        return;
    };
    let (h, entries) = (r.header().clone(), r.entries().to_vec());
    let need = crate::player::memory_needed(&h, &entries, 0, (1, true));
    if LIMITS.check("fuzz", need).is_err() || h.segment_count == 0 {
        return;
    }
    let mut core = DecoderCore::new(h, r.layout().clone(), entries);
    let mut out = SegmentData::new();
    // Twice: the second pass meets the parsed keyframes the first left (a loop).
    for pass in 0..2 {
        for i in 0..r.entries().len() {
            let bytes = r.read_chunk(i).ok();
            if let Event::Ready(s) = core.take(i, bytes.as_deref()) {
                let _ = core.fill(s, 0, pass, &mut out);
            }
        }
    }
}
