//! A counting allocator: no allocation on the render thread over 1000 steady-state frames,
//! and no growth in what the other threads hold.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Cursor;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

use vbim_encoder::{encode, EncoderConfig, InputKind, MemorySource, Preset, SegmentMode};
use vbim_player::{headless_device, FrameState, Player, PlayerConfig};

struct Counting;

thread_local! {
    static COUNT_HERE: Cell<bool> = const { Cell::new(false) };
}
static HERE: AtomicU64 = AtomicU64::new(0);
static LIVE: AtomicI64 = AtomicI64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNT_HERE.try_with(|c| c.get()).unwrap_or(false) {
            HERE.fetch_add(1, Ordering::Relaxed);
        }
        LIVE.fetch_add(l.size() as i64, Ordering::Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        LIVE.fetch_sub(l.size() as i64, Ordering::Relaxed);
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        if COUNT_HERE.try_with(|c| c.get()).unwrap_or(false) {
            HERE.fetch_add(1, Ordering::Relaxed);
        }
        LIVE.fetch_add(new as i64 - l.size() as i64, Ordering::Relaxed);
        unsafe { System.realloc(p, l, new) }
    }
}

#[global_allocator]
static A: Counting = Counting;

/// Runs `f`, counting the allocations this thread makes in it.
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    HERE.store(0, Ordering::Relaxed);
    COUNT_HERE.with(|c| c.set(true));
    let out = f();
    COUNT_HERE.with(|c| c.set(false));
    (out, HERE.swap(0, Ordering::Relaxed))
}

#[test]
fn steady_state_frames_do_not_allocate() {
    let (device, queue, _) = headless_device().unwrap_or_else(|e| panic!("{e}"));
    let (w, h, n) = (64, 32, 96);
    let frames = (0..n)
        .map(|t| {
            (0..w * h)
                .flat_map(|i| {
                    let v =
                        0.1 + 0.5 * ((i % w) as f32 / w as f32) * (1.0 + (t as f32 * 0.1).sin());
                    [v, v, v]
                })
                .collect()
        })
        .collect();
    let src = MemorySource::new("m", w, h, 3, InputKind::Hdr, frames);
    let cfg = EncoderConfig {
        segment: SegmentMode::Fixed(8),
        rate: (24, 1),
        ..EncoderConfig::preset(Preset::Default)
    };
    let mut bytes = Vec::new();
    encode(&src, &cfg, Cursor::new(&mut bytes), &|_, _, _| {}).unwrap();
    let mut player =
        Player::open(&device, &queue, Cursor::new(bytes), PlayerConfig::default()).unwrap();
    // Warm up: every segment has gone through both slots once.
    let dt = 16_666_667;
    for _ in 0..600 {
        player.advance(dt);
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    let live_before = LIVE.load(Ordering::Relaxed);
    let mut exact = 0;
    let (mut ours, mut wgpu) = (0, 0);
    for _ in 0..1000 {
        // The player's own work on the render thread (`plan`), then wgpu's (`render`:
        // write_texture, write_buffer, a command encoder and a submit), counted apart.
        let (frame, n) = counted(|| player.plan(dt));
        ours += n;
        wgpu += counted(|| player.render(&frame)).1;
        exact += (frame.record.state == FrameState::Exact) as u32;
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    let growth = LIVE.load(Ordering::Relaxed) - live_before;
    // Recorded into the caller's encoder instead (`advance_into`, then `submitted`), the
    // player's share of a frame is the recording alone: the encoder and the submission
    // are the renderer's, not counted here.
    let (mut ours_into, mut wgpu_into) = (0, 0);
    for _ in 0..1000 {
        let mut encoder = device.create_command_encoder(&Default::default());
        let (frame, n) = counted(|| player.plan(dt));
        ours_into += n;
        wgpu_into += counted(|| player.render_into(&frame, &mut encoder)).1;
        queue.submit([encoder.finish()]);
        wgpu_into += counted(|| player.submitted()).1;
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    eprintln!(
        "recorded into the caller's encoder: {ours_into} allocations by the player, {:.1} per \
         frame inside wgpu's recording",
        wgpu_into as f64 / 1000.0
    );
    assert_eq!(
        ours_into, 0,
        "the player allocated {ours_into} times planning 1000 frames recorded into the caller's encoder"
    );
    // wgpu's floor, for the figure above: an empty command encoder, finished and
    // submitted, on the same device.
    let ((), empty) = counted(|| {
        for _ in 0..1000 {
            let encoder = device.create_command_encoder(&Default::default());
            queue.submit([encoder.finish()]);
        }
    });
    eprintln!(
        "an empty wgpu frame (encoder, finish, submit) allocates {:.1} times",
        empty as f64 / 1000.0
    );
    eprintln!(
        "over 1000 frames: {ours} allocations by the player on the render thread, {wgpu} inside wgpu's \
         recording and submit ({:.1} per frame); live-heap growth {growth} bytes; exact frames {exact}",
        wgpu as f64 / 1000.0
    );
    assert_eq!(
        ours, 0,
        "the player allocated {ours} times on the render thread in 1000 steady-state frames"
    );
    // Mostly exact frames: the pipeline kept up (a loaded machine may hold a few).
    assert!(exact > 500, "steady state: only {exact} exact frames");
    assert!(growth.abs() < 1 << 20, "live heap grew by {growth} bytes");
}
