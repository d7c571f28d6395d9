//! The CPU reference decoder stays within the memory its limit check counts
//! (`vbim_format::decoder_memory`), measured by a counting allocator while it
//! decodes every frame of a day, seeks included. (A test binary of its own: the counter
//! sees every thread of the process.)

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Cursor;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

use vbim_encoder::{
    encode, EncoderConfig, FormatVersion, InputKind, MemorySource, Preset, SegmentMode,
};
use vbim_format::decode::{Decoder, Output};
use vbim_format::{Limits, Reader};

struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let live = LIVE.fetch_add(l.size(), Relaxed) + l.size();
        PEAK.fetch_max(live, Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        LIVE.fetch_sub(l.size(), Relaxed);
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static A: Counting = Counting;

/// A day-like sequence: a soft shadow edge sweeping over a textured gradient.
fn day(w: usize, h: usize, n: usize) -> MemorySource {
    let frames = (0..n)
        .map(|t| {
            let sun = (std::f32::consts::PI * t as f32 / n as f32).sin().max(0.0);
            (0..w * h)
                .flat_map(|i| {
                    let (x, y) = ((i % w) as f32, (i / w) as f32);
                    let edge = 1.0 / (1.0 + (-(x - w as f32 * t as f32 / n as f32) * 0.4).exp());
                    let v = 0.02 + sun * (0.3 + 0.6 * edge) * (0.8 + 0.2 * (x * y * 0.01).sin());
                    [v, v * 0.9, v * 0.75]
                })
                .collect()
        })
        .collect();
    MemorySource::new("day", w, h, 3, InputKind::Hdr, frames)
}

/// Every format version, one after the other: the counter sees every thread of the
/// process, so this binary holds one test.
#[test]
fn the_decoder_holds_no_more_than_its_limit_check_counts() {
    holds_no_more_than_counted(FormatVersion::V1);
    holds_no_more_than_counted(FormatVersion::V2);
    holds_no_more_than_counted(FormatVersion::V3);
}

fn holds_no_more_than_counted(format: FormatVersion) {
    let src = day(200, 136, 48);
    let cfg = EncoderConfig {
        segment: SegmentMode::Auto { max: 12 },
        format,
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(&src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    let open = || Reader::open(Cursor::new(bytes.clone())).unwrap();
    let reader = open();
    let h = reader.header().clone();
    let bound = vbim_format::decoder_memory(&h, reader.entries());
    let mut out = vec![0f32; h.texel_count() * h.channels as usize];
    // Just under the bound is refused...
    let Err(e) = Decoder::with_limits(reader, Limits { memory: bound - 1 }) else {
        panic!("a limit one byte under the need must refuse")
    };
    assert!(e.to_string().contains("200×136"), "{e}");
    // ...and at the bound everything decodes, frame by frame, backwards (each frame a
    // seek through the predicted chain) and again forwards, within it.
    let reader = open();
    let base = LIVE.load(Relaxed);
    PEAK.store(base, Relaxed);
    let mut d = Decoder::with_limits(reader, Limits { memory: bound }).unwrap();
    for i in (0..h.frame_count).rev().chain(0..h.frame_count) {
        d.frame(i as f64, Output::Stored, &mut out).unwrap();
    }
    let held = PEAK.load(Relaxed) - base;
    assert!(
        held as u64 <= bound,
        "held {held} bytes at the peak, the limit check counts {bound}"
    );
    // The bound is not vacuous: the planes are most of it.
    assert!(held as u64 * 3 > bound, "held {held} of {bound}");
    eprintln!("held {held} bytes at the peak of {bound} counted");
}
