//! The player: the reader and decoder (on their own threads, or stepped inline for
//! deterministic simulated time), the render-thread state machine that decides what to
//! show under each stall policy, and the per-frame record of what it did.

use std::io::{Read, Seek};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{bounded, Receiver, Sender, TryRecvError};
use ringbuf::traits::Split;
use ringbuf::{HeapCons, HeapProd, HeapRb};
use vbim_format::{Header, Reader, Transfer};

use crate::assemble::{DecoderCore, Event, SegmentData};
use crate::clock::{Clock, SystemClock};
use crate::gpu::{Gpu, Params, UploadPlan, KEY_SLOTS};
use crate::stream::{pop_message, ReaderCore};
use crate::throttle::Throttle;
use crate::time::{frames_f64, media_to_ticks, ticks_to_media, MediaTime, ONE_FRAME};
use crate::PlayerError;

/// After a re-synchronisation, how long to let the reader catch up before another.
const SEEK_COOLDOWN_NS: u64 = 2_000_000_000;

/// What the display does when the next segment's data is late.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Policy {
    /// The clock runs on; the last resident state is held, and when the data arrives the
    /// display blends from what is shown to the true state over the catch-up window.
    Interpolate,
    /// The clock pauses until the data is there: drift accumulates, no error is shown.
    Wait,
    /// The display holds, then jumps to the true state when the data arrives.
    Skip,
}

impl std::str::FromStr for Policy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "interpolate" => Ok(Policy::Interpolate),
            "wait" => Ok(Policy::Wait),
            "skip" => Ok(Policy::Skip),
            _ => Err(format!("policy {s:?} (interpolate, wait or skip)")),
        }
    }
}

#[derive(Clone)]
pub struct PlayerConfig {
    pub policy: Policy,
    /// Catch-up window, ns of playback.
    pub catch_up_ns: u64,
    /// The reader's bandwidth cap and stall pattern.
    pub throttle: Throttle,
    /// Ring capacity in bytes; `None`: the header's read-ahead at the throttle's rate (the
    /// largest tabulated point when unthrottled), and never less than the largest chunk.
    pub ring_bytes: Option<usize>,
    /// Run reader and decoder on their own threads (the default), or step them inside
    /// `advance` — deterministic, for simulated time.
    pub threaded: bool,
    /// The clock that paces the reader thread (threaded mode).
    pub clock: Arc<dyn Clock>,
    /// How long to buffer before the first frame; `None`: the header's buffer model at the
    /// throttle's rate (no wait when unthrottled).
    pub preroll_ns: Option<u64>,
    /// Added to the pre-roll. The buffer model's pre-roll assumes a reader that never
    /// stalls; while the ring is still filling after it, a stall can make the first
    /// transition late. A margin as long as the stall to survive buys that back with
    /// start-up time (measured in BENCHMARKS.md).
    pub preroll_margin_ns: u64,
}

impl Default for PlayerConfig {
    fn default() -> Self {
        PlayerConfig {
            policy: Policy::Interpolate,
            catch_up_ns: 500_000_000,
            throttle: Throttle::UNLIMITED,
            ring_bytes: None,
            threaded: true,
            clock: Arc::new(SystemClock::new()),
            preroll_ns: None,
            preroll_margin_ns: 0,
        }
    }
}

/// What a displayed frame showed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameState {
    /// The true state at the target time.
    Exact,
    /// Data late: the last resident state is held.
    Held,
    /// Blending from the held image to the true state.
    CatchingUp,
    /// `wait` policy: the clock is paused for data.
    Waiting,
}

impl FrameState {
    pub fn name(self) -> &'static str {
        match self {
            FrameState::Exact => "exact",
            FrameState::Held => "held",
            FrameState::CatchingUp => "catching_up",
            FrameState::Waiting => "waiting",
        }
    }
}

/// One displayed frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameRecord {
    pub index: u64,
    /// Playback clock, ns.
    pub clock_ns: u64,
    /// Target and shown media time, frames (not wrapped at loops).
    pub target: f64,
    pub shown: f64,
    /// target − shown, frames.
    pub drift: f64,
    pub state: FrameState,
    /// Bytes the reader delivered since the previous frame.
    pub bytes_read: u64,
    /// Bytes uploaded to the GPU this frame.
    pub bytes_uploaded: u64,
    /// Decoder CPU time (the decoding thread's own clock) charged to segments received
    /// this frame, ns.
    pub decode_ns: u64,
    /// Time spent in `advance` on the calling thread, ns.
    pub render_ns: u64,
    /// Blend weight of the true state while catching up (1 otherwise).
    pub alpha: f32,
    /// The segment shown and its normalised time.
    pub segment: usize,
    pub u: f64,
}

/// A planned frame: its record and the reconstruction to run (slot, parameters, whether
/// to keep the current image for blending first).
pub struct Frame {
    pub record: FrameRecord,
    pub eval: Option<(usize, Params, bool)>,
}

/// Running totals.
#[derive(Clone, Debug, Default)]
pub struct Totals {
    pub frames: u64,
    pub stalls: u64,
    pub bytes_read: u64,
    pub bytes_uploaded: u64,
    pub decode_ns: u64,
    pub segments_uploaded: u64,
    pub segments_dropped: u64,
    pub damaged: u64,
    pub seeks: u64,
    pub last_error: Option<String>,
}

/// A segment resident in a GPU slot, with its absolute frame range (pass · N + frames).
#[derive(Clone, Copy, Debug)]
struct Resident {
    index: usize,
    start: u64,
    end: u64,
    layers: usize,
    /// Keyframe slots holding its K_s and K_{s+1}.
    keys: [usize; 2],
}

// Staging buffers travel as the same boxes through channels and these pools.
#[allow(clippy::vec_box)]
enum Pipeline<R> {
    Threaded {
        stop: Arc<AtomicBool>,
        seek: Sender<(usize, u32, Option<usize>)>,
        throttle: Sender<Throttle>,
        threads: Vec<JoinHandle<()>>,
        ready: Receiver<Box<SegmentData>>,
        errors: Receiver<String>,
        bytes_read: Arc<AtomicU64>,
        read_seen: u64,
    },
    Inline {
        reader: Box<ReaderCore<R>>,
        prod: HeapProd<u8>,
        cons: HeapCons<u8>,
        decoder: Box<DecoderCore>,
        msg: Vec<u8>,
        pool: Vec<Box<SegmentData>>,
        ready: Vec<Box<SegmentData>>,
        read_seen: u64,
    },
}

pub struct Player<R: Read + Seek + Send + 'static> {
    header: Header,
    layout: vbim_format::index::Layout,
    entries: Vec<vbim_format::IndexEntry>,
    cfg: PlayerConfig,
    gpu: Gpu,
    pipeline: Pipeline<R>,
    /// Staging buffers going back to the decoder after upload.
    recycle: Sender<Box<SegmentData>>,
    /// The box received but not yet uploaded.
    incoming: Option<Box<SegmentData>>,
    /// A box planned for upload this frame, and what to copy from it.
    to_upload: Option<(UploadPlan, Box<SegmentData>)>,
    /// Uploaded boxes whose staging buffers are not mapped again yet (at most two; the
    /// boxes themselves travel back to the decoder, so they stay boxed).
    #[allow(clippy::vec_box)]
    remapping: Vec<Box<SegmentData>>,
    /// The box uploaded by the last `render_into`, until its encoder is submitted.
    awaiting_submit: Option<Box<SegmentData>>,
    slots: [Option<Resident>; 2],
    shown_slot: Option<usize>,
    /// Which keyframe (by number) each GPU keyframe slot holds.
    key_slots: [Option<usize>; KEY_SLOTS],
    ticks: u64,
    paused: u64,
    /// Start of a catch-up (ticks) and the lag the data arrived with.
    catch_start: Option<(u64, MediaTime)>,
    last_shown: MediaTime,
    was_missing: bool,
    generation: u32,
    last_seek: u64,
    started: bool,
    startup: u64,
    read_reported: u64,
    frame: u64,
    totals: Totals,
    ring_bytes: usize,
    /// Buffering before the first frame, ns.
    preroll: u64,
}

fn ring_capacity(h: &Header, entries: &[vbim_format::IndexEntry], cfg: &PlayerConfig) -> usize {
    let largest =
        entries.iter().map(|e| e.length).max().unwrap_or(0) as usize + crate::stream::MSG_HEADER;
    let model = match cfg.throttle.rate {
        Some(r) => h
            .read_ahead_at(r)
            .map(|p| p.bytes)
            .unwrap_or_else(|| h.read_ahead.iter().map(|p| p.bytes).max().unwrap_or(0)),
        None => h.read_ahead.iter().map(|p| p.bytes).max().unwrap_or(0),
    } as usize;
    cfg.ring_bytes.unwrap_or(model).max(largest) + crate::stream::MSG_HEADER * 4
}

impl<R: Read + Seek + Send + 'static> Player<R> {
    /// Opens a stream on `device`. Reads and validates the header and index first.
    pub fn open(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        src: R,
        cfg: PlayerConfig,
    ) -> Result<Self, PlayerError> {
        let reader = Reader::open(src)?;
        let header = reader.header().clone();
        let entries = reader.entries().to_vec();
        let layout = reader.layout().clone();
        let src = reader.into_inner();
        if header.segment_count == 0 {
            return Err(PlayerError::Unsupported(
                "a single-frame sequence that does not loop has nothing to play".into(),
            ));
        }
        let ring_bytes = ring_capacity(&header, &entries, &cfg);
        let preroll = cfg.preroll_ns.unwrap_or_else(|| {
            cfg.throttle.rate.map_or(0, |r| {
                header.read_ahead_at(r).map_or_else(
                    || {
                        header
                            .read_ahead
                            .iter()
                            .map(|p| p.preroll_ns)
                            .max()
                            .unwrap_or(0)
                    },
                    |p| p.preroll_ns,
                )
            })
        }) + cfg.preroll_margin_ns;
        let (prod, cons) = HeapRb::<u8>::new(ring_bytes).split();
        let mut reader_core = ReaderCore::new(src, entries.clone(), header.looping, cfg.throttle);
        let player_entries = entries.clone();
        let player_layout = layout.clone();
        let decoder = DecoderCore::new(header.clone(), layout.clone(), entries.clone());
        let (recycle_tx, recycle_rx) = bounded::<Box<SegmentData>>(2);
        for _ in 0..2 {
            recycle_tx
                .send(Box::new(SegmentData::mapped(&header, device)))
                .expect("room for two");
        }
        let gpu = Gpu::new(
            device,
            queue,
            header.width,
            header.height,
            header.max_degree as u32 + 1,
            header.channels as u32,
        );
        let pipeline = if cfg.threaded {
            let stop = Arc::new(AtomicBool::new(false));
            let bytes_read = Arc::new(AtomicU64::new(0));
            let (ready_tx, ready_rx) = bounded::<Box<SegmentData>>(2);
            let (err_tx, err_rx) = bounded::<String>(64);
            let (seek_tx, seek_rx) = bounded::<(usize, u32, Option<usize>)>(16);
            let (throttle_tx, throttle_rx) = bounded::<Throttle>(16);
            let clock = cfg.clock.clone();
            let (s1, s2) = (stop.clone(), stop.clone());
            let br = bytes_read.clone();
            // Each thread wakes the other through the ring: the reader after a chunk goes
            // in, the decoder after one comes out (set once both threads exist).
            let (wake_reader, wake_decoder) = (Waker::default(), Waker::default());
            let (wr, wd) = (wake_reader.clone(), wake_decoder.clone());
            let reader_thread = std::thread::Builder::new()
                .name("vbim-reader".into())
                .spawn(move || {
                    reader_loop(
                        &mut reader_core,
                        prod,
                        &*clock,
                        &s1,
                        &br,
                        &seek_rx,
                        &throttle_rx,
                        &wd,
                    )
                })
                .map_err(|e| PlayerError::Thread(e.to_string()))?;
            let mut dec = decoder;
            let decoder_thread = std::thread::Builder::new()
                .name("vbim-decoder".into())
                .spawn(move || decoder_loop(&mut dec, cons, recycle_rx, ready_tx, err_tx, &s2, &wr))
                .map_err(|e| PlayerError::Thread(e.to_string()))?;
            let _ = wake_reader.set(reader_thread.thread().clone());
            let _ = wake_decoder.set(decoder_thread.thread().clone());
            Pipeline::Threaded {
                stop,
                seek: seek_tx,
                throttle: throttle_tx,
                threads: vec![reader_thread, decoder_thread],
                ready: ready_rx,
                errors: err_rx,
                bytes_read,
                read_seen: 0,
            }
        } else {
            let pool: Vec<Box<SegmentData>> = recycle_rx.try_iter().collect();
            reader_core.prepare(0);
            Pipeline::Inline {
                reader: Box::new(reader_core),
                prod,
                cons,
                decoder: Box::new(decoder),
                msg: Vec::with_capacity(1 << 20),
                ready: Vec::with_capacity(2),
                pool,
                read_seen: 0,
            }
        };
        Ok(Player {
            header,
            layout: player_layout,
            entries: player_entries,
            cfg,
            gpu,
            pipeline,
            recycle: recycle_tx,
            incoming: None,
            to_upload: None,
            remapping: Vec::with_capacity(2),
            awaiting_submit: None,
            slots: [None, None],
            shown_slot: None,
            key_slots: [None; KEY_SLOTS],
            ticks: 0,
            paused: 0,
            catch_start: None,
            last_shown: 0,
            was_missing: false,
            generation: 0,
            last_seek: 0,
            started: false,
            startup: 0,
            read_reported: 0,
            frame: 0,
            totals: Totals::default(),
            ring_bytes,
            preroll,
        })
    }

    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The lightmap (linear RGB, Rgba16Float) the renderer samples.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.gpu.display_view
    }
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }
    pub fn totals(&self) -> &Totals {
        &self.totals
    }
    /// Buffering before the first frame, ns (the pre-roll and its margin).
    pub fn preroll_ns(&self) -> u64 {
        self.preroll
    }
    pub fn ring_bytes(&self) -> usize {
        self.ring_bytes
    }
    /// Playback clock, ns.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
    pub fn policy(&self) -> Policy {
        self.cfg.policy
    }
    pub fn set_policy(&mut self, p: Policy) {
        self.cfg.policy = p;
    }

    /// Changes the reader's bandwidth cap and stalls from now on (inline mode: at once;
    /// threaded mode: at the reader's next chunk).
    pub fn set_throttle(&mut self, t: Throttle) {
        self.cfg.throttle = t;
        match &mut self.pipeline {
            Pipeline::Inline { reader, .. } => reader.throttle = t,
            Pipeline::Threaded {
                throttle, threads, ..
            } => {
                let _ = throttle.try_send(t);
                unpark_reader(threads);
            }
        }
    }

    fn n_frames(&self) -> u64 {
        self.header.frame_count as u64
    }

    /// Moves the pipeline forward and takes decoded segments (never blocks).
    fn pump(&mut self) -> u64 {
        let mut decode_ns = 0;
        match &mut self.pipeline {
            Pipeline::Threaded {
                ready,
                errors,
                bytes_read,
                read_seen,
                ..
            } => {
                while let Ok(e) = errors.try_recv() {
                    self.totals.damaged += 1;
                    self.totals.last_error = Some(e);
                }
                if self.incoming.is_none() {
                    match ready.try_recv() {
                        Ok(b) => {
                            decode_ns += b.decode_ns;
                            self.incoming = Some(b);
                        }
                        Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => {}
                    }
                }
                let r = bytes_read.load(Ordering::Relaxed);
                self.totals.bytes_read += r - *read_seen;
                *read_seen = r;
            }
            Pipeline::Inline {
                reader,
                prod,
                cons,
                decoder,
                msg,
                pool,
                ready,
                read_seen,
            } => {
                let now = self.ticks;
                loop {
                    let mut progress = false;
                    reader.prepare(now);
                    if reader.deliver(now, prod) {
                        progress = true;
                    }
                    // Decode only while a staging buffer is free (the render thread returns
                    // them after upload): the natural back-pressure of double buffering.
                    while !pool.is_empty() {
                        let Some(m) = pop_message(cons, msg) else {
                            break;
                        };
                        progress = true;
                        if m.generation != reader.generation {
                            continue;
                        }
                        match decoder.take(m.chunk as usize, m.ok.then_some(&msg[..])) {
                            Event::Ready(s) => {
                                let mut b = pool.pop().unwrap();
                                match decoder.fill(s, m.generation, m.pass, &mut b) {
                                    Ok(()) => ready.push(b),
                                    Err(e) => {
                                        self.totals.damaged += 1;
                                        self.totals.last_error = Some(e);
                                        pool.push(b);
                                    }
                                }
                            }
                            Event::Damaged(e) => {
                                self.totals.damaged += 1;
                                self.totals.last_error = Some(e);
                            }
                            Event::Nothing => {}
                        }
                    }
                    if !progress {
                        break;
                    }
                }
                if self.incoming.is_none() && !ready.is_empty() {
                    let b = ready.remove(0);
                    decode_ns += b.decode_ns;
                    self.incoming = Some(b);
                }
                self.totals.bytes_read += reader.bytes_read - *read_seen;
                *read_seen = reader.bytes_read;
            }
        }
        decode_ns
    }

    fn give_back(&mut self, b: Box<SegmentData>) {
        match &mut self.pipeline {
            Pipeline::Inline { pool, .. } => pool.push(b),
            Pipeline::Threaded { .. } => {
                let _ = self.recycle.try_send(b);
            }
        }
    }

    /// Puts an arrived segment in the bubble slot that is not on screen (never the
    /// displayed one) and its keyframes in keyframe slots the other bubble slot does not
    /// use, or drops it when it is already in the past. A dropped segment still leaves its
    /// closing keyframe on the GPU: the decoder did not stage it again for the next one.
    fn take_incoming(&mut self, b: Box<SegmentData>, pos: MediaTime, n: u64, uploaded: &mut u64) {
        let base = b.pass as u64 * n;
        let r = Resident {
            index: b.index,
            start: base + ((b.start as u64) << 32),
            end: base + ((b.end as u64) << 32),
            layers: b.layers,
            keys: [0, 0],
        };
        let free = self.shown_slot.map_or(0, |s| 1 - s);
        let last_of_still = !self.header.looping && r.end >= n - ONE_FRAME;
        let past = r.end <= pos && !last_of_still;
        if !past
            && self.slots[free]
                .is_some_and(|old| old.end > pos && r.start > pos && old.start <= r.start)
        {
            // The slot not on screen holds a segment still to come: wait for it to play.
            self.incoming = Some(b);
            return;
        }
        if !past {
            let keep = [self.slots[1 - free], None];
            if let Some((mut plan, keys)) = self.place_keys(&b, keep) {
                plan.bubbles = Some(free);
                *uploaded = plan.bytes(&b, &self.header);
                self.slots[free] = Some(Resident { keys, ..r });
                self.totals.segments_uploaded += 1;
                // Copied to the GPU in `render`, after which the box goes back to the decoder.
                self.to_upload = Some((plan, b));
                return;
            }
            // Its K_s is neither staged nor on the GPU (only if a closing keyframe could
            // not be kept, below): drop it like a late one; the next segment plays.
        }
        self.totals.segments_dropped += 1;
        let mut placed = self.place_closing(&b);
        if placed.is_none() {
            // Both bubble slots' keyframes are protected: forget the one not on screen if
            // it is over (it can never be shown again).
            let other = self.shown_slot.map_or(1, |s| 1 - s);
            if self.slots[other].is_some_and(|o| o.end <= pos) {
                self.slots[other] = None;
                placed = self.place_closing(&b);
            }
        }
        match placed {
            Some(plan) if plan.key1.is_some() => {
                *uploaded = plan.bytes(&b, &self.header);
                self.to_upload = Some((plan, b));
            }
            _ => self.give_back(b),
        }
    }

    /// Keyframe slots for a dropped segment's closing keyframe, keeping both bubble
    /// slots' keyframes.
    fn place_closing(&mut self, b: &SegmentData) -> Option<UploadPlan> {
        let keep = [self.slots[0], self.slots[1]];
        let (slot, copy) = self.key_slot_for(b.keys[1], keep, None)?;
        self.key_slots[slot] = Some(b.keys[1]);
        Some(UploadPlan {
            key0: None,
            key1: copy,
            bubbles: None,
        })
    }

    /// Keyframe slots for segment `b`'s K_s and K_{s+1}: where they already are, or
    /// slots that no segment in `keep` uses. `None` if K_s is neither staged nor resident.
    fn place_keys(
        &mut self,
        b: &SegmentData,
        keep: [Option<Resident>; 2],
    ) -> Option<(UploadPlan, [usize; 2])> {
        let (k0, copy0) = self.key_slot_for(b.keys[0], keep, None)?;
        if copy0.is_some() && !b.k0_staged {
            return None;
        }
        let (k1, copy1) = self.key_slot_for(b.keys[1], keep, Some(k0))?;
        self.key_slots[k0] = Some(b.keys[0]);
        self.key_slots[k1] = Some(b.keys[1]);
        let plan = UploadPlan {
            key0: copy0,
            key1: copy1,
            bubbles: None,
        };
        Some((plan, [k0, k1]))
    }

    /// The keyframe slot for keyframe `k`: the one that holds it already (nothing to
    /// copy), or a free one (see [`Self::free_key_slot`]) to copy it into — `(slot, copy)`.
    fn key_slot_for(
        &self,
        k: usize,
        keep: [Option<Resident>; 2],
        avoid: Option<usize>,
    ) -> Option<(usize, Option<usize>)> {
        match self.key_slots.iter().position(|&x| x == Some(k)) {
            Some(s) => Some((s, None)),
            None => self.free_key_slot(keep, avoid).map(|s| (s, Some(s))),
        }
    }

    /// A keyframe slot that no segment in `keep` uses, other than `avoid`: an empty one
    /// first.
    fn free_key_slot(&self, keep: [Option<Resident>; 2], avoid: Option<usize>) -> Option<usize> {
        let usable =
            |s: usize| Some(s) != avoid && !keep.iter().flatten().any(|r| r.keys.contains(&s));
        (0..KEY_SLOTS)
            .find(|&s| usable(s) && self.key_slots[s].is_none())
            .or_else(|| (0..KEY_SLOTS).find(|&s| usable(s)))
    }

    fn covers(r: &Option<Resident>, p: u64) -> bool {
        r.is_some_and(|r| r.start <= p && p < r.end)
    }

    /// Advances playback by `dt` ns and renders the lightmap for the new time: [`plan`]
    /// then [`render`].
    ///
    /// [`plan`]: Player::plan
    /// [`render`]: Player::render
    pub fn advance(&mut self, dt: u64) -> FrameRecord {
        let t0 = Instant::now();
        let frame = self.plan(dt);
        self.render(&frame);
        let mut r = frame.record;
        r.render_ns = t0.elapsed().as_nanos() as u64;
        r
    }

    /// Records the GPU work of a planned frame: the upload of a newly arrived segment into
    /// the slot not on screen, and the reconstruction, in one submission of its own.
    pub fn render(&mut self, frame: &Frame) {
        let mut encoder = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        self.render_into(frame, &mut encoder);
        self.gpu.queue.submit(Some(encoder.finish()));
        self.submitted();
    }

    /// Like [`advance`], but records the frame's GPU work into the caller's encoder instead
    /// of submitting a command buffer of its own, for a renderer that submits once per
    /// frame. Submit `encoder` (it must be the next submission on the player's queue that
    /// carries this work), then call [`submitted`] before the next frame: only then can
    /// the staging buffer of an upload be mapped again for the decoder.
    ///
    /// [`advance`]: Player::advance
    /// [`submitted`]: Player::submitted
    pub fn advance_into(&mut self, dt: u64, encoder: &mut wgpu::CommandEncoder) -> FrameRecord {
        let t0 = Instant::now();
        let frame = self.plan(dt);
        self.render_into(&frame, encoder);
        let mut r = frame.record;
        r.render_ns = t0.elapsed().as_nanos() as u64;
        r
    }

    /// Records the GPU work of a planned frame into `encoder` (see [`Player::advance_into`]).
    pub fn render_into(&mut self, frame: &Frame, encoder: &mut wgpu::CommandEncoder) {
        // A caller that skipped `submitted` for the last frame: catch up now (right if
        // that frame's encoder was submitted, which the contract asks for).
        self.submitted();
        let up = self.to_upload.take();
        let eval = frame.eval.as_ref().map(|(s, p, h)| (*s, p, *h));
        self.gpu
            .record(encoder, up.as_ref().map(|(plan, b)| (*plan, &**b)), eval);
        self.awaiting_submit = up.map(|(_, b)| b);
    }

    /// Tells the player that the encoder of its last [`Player::advance_into`] was
    /// submitted: a staging buffer it uploaded from is mapped again, and goes back to the
    /// decoder once it is. Harmless when there is nothing to do.
    pub fn submitted(&mut self) {
        if let Some(b) = self.awaiting_submit.take() {
            self.gpu.remap(&b);
            if matches!(self.pipeline, Pipeline::Inline { .. }) {
                // Simulated time stays deterministic: the buffer is mapped again now
                // rather than at whichever later submission the GPU happens to finish by.
                self.gpu.wait();
            }
            self.remapping.push(b);
            self.return_mapped();
        }
    }

    /// Gives the staging boxes whose buffers are mapped again back to the decoder.
    fn return_mapped(&mut self) {
        let mut i = 0;
        while i < self.remapping.len() {
            if self.remapping[i].mapped.load(Ordering::Acquire) {
                let b = self.remapping.swap_remove(i);
                self.give_back(b);
            } else {
                i += 1;
            }
        }
    }

    /// The CPU side of a frame, allocation-free: takes what the reader and decoder
    /// produced, decides what is shown under the policy, and computes the shader's weights.
    pub fn plan(&mut self, dt: u64) -> Frame {
        let t0 = Instant::now();
        self.ticks += dt;
        self.return_mapped();
        let decode_ns = self.pump();
        let (num, den) = (self.header.rate_num, self.header.rate_den);
        let n = self.n_frames() << 32;
        // Playback starts when the first segment is resident (pre-roll is not drift).
        let wall = ticks_to_media(self.ticks - self.startup, num, den);
        let mut pos = ticks_to_media(self.ticks - self.startup - self.paused, num, den);
        if !self.header.looping {
            pos = pos.min(n - ONE_FRAME);
        }
        // Take an arrived segment: drop it if already in the past, else put it in the slot
        // that is not on screen (never the displayed one).
        let mut uploaded = 0;
        if let Some(b) = self.incoming.take() {
            if b.generation != self.generation {
                // Decoded before a seek: no longer wanted.
                self.give_back(b);
            } else {
                self.take_incoming(b, pos, n, &mut uploaded);
            }
        }
        let mut state = FrameState::Exact;
        let covering = (0..2).find(|&s| Self::covers(&self.slots[s], pos));
        let missing = covering.is_none();
        if let Some(s) = covering {
            self.shown_slot = Some(s);
        }
        if missing && self.ticks.saturating_sub(self.last_seek) > SEEK_COOLDOWN_NS {
            // So far behind that reading on would only deliver the past: re-synchronise
            // at the last intra keyframe before the target.
            let known_end = self
                .slots
                .iter()
                .flatten()
                .map(|r| r.end)
                .max()
                .unwrap_or(0);
            if pos.saturating_sub(known_end) > (n / 2).max(ONE_FRAME) {
                self.last_seek = self.ticks;
                self.seek(pos);
            }
        }
        let mut shown = pos;
        let mut alpha = 1.0f32;
        let mut hold_first = false;
        if !self.started && (missing || self.ticks < self.preroll) {
            // Start-up (pre-roll): the buffer model's pre-roll, and at least the first
            // segment, before the clock starts, whatever the policy; reported as waiting.
            self.startup = self.ticks;
            self.was_missing = false;
            // Target and shown are both the start: pre-roll is not drift (`wall` still
            // counted this frame's step).
            let record = self.record(
                t0,
                0,
                0,
                FrameState::Waiting,
                1.0,
                0,
                0.0,
                uploaded,
                decode_ns,
            );
            return Frame { record, eval: None };
        }
        self.started = true;
        if missing {
            // Hold the end of what is on screen (its closing keyframe), or its start.
            let held = self
                .shown_slot
                .and_then(|s| self.slots[s])
                .map_or(self.last_shown, |r| {
                    if pos >= r.end {
                        r.end - 1
                    } else {
                        r.start
                    }
                });
            if !self.was_missing {
                self.totals.stalls += 1;
            }
            shown = held.min(pos);
            if self.cfg.policy == Policy::Wait {
                // Pause the clock at the held time.
                let run = self.ticks - self.startup;
                self.paused = run - media_to_ticks(shown, num, den).min(run);
                state = FrameState::Waiting;
            } else {
                state = FrameState::Held;
            }
            self.catch_start = None;
        } else if self.was_missing && self.cfg.policy == Policy::Interpolate && self.frame > 0 {
            // The data arrived: blend from the held image over the catch-up window.
            let held_shown = self.last_shown;
            self.catch_start = Some((self.ticks, pos.saturating_sub(held_shown)));
            hold_first = true;
        }
        if !missing {
            if let Some((start, lag)) = self.catch_start {
                let a = ((self.ticks - start) as f64 / self.cfg.catch_up_ns.max(1) as f64).min(1.0);
                if a >= 1.0 {
                    self.catch_start = None;
                } else {
                    alpha = a.max(1e-3) as f32;
                    state = FrameState::CatchingUp;
                    // The lag the data arrived with fades out with the blend: a short
                    // stall leaves a short lag, however long the blend.
                    shown = pos.saturating_sub(((1.0 - a) * lag as f64) as u64);
                }
            }
        }
        self.was_missing = missing;
        // Evaluate the shown slot at the (clamped) time.
        let (mut seg, mut u) = (0, 0.0);
        let mut eval = None;
        if let Some(s) = self.shown_slot {
            if let Some(r) = self.slots[s] {
                let t = if missing {
                    shown.clamp(r.start, r.end)
                } else {
                    pos
                };
                u = ((t - r.start) as f64 / (r.end - r.start) as f64).clamp(0.0, 1.0);
                seg = r.index;
                let dmax = r.layers - 1;
                let w = vbim_format::basis::weights(dmax, u);
                let mut params = Params::zeroed_params();
                params.w[..w.len()].copy_from_slice(&w);
                params.size = [self.header.width, self.header.height];
                params.layers = r.layers as u32;
                let (tr, v0) = match self.header.transfer {
                    Transfer::Srgb => (0, 0.0),
                    Transfer::LogToe { v0 } => (1, v0),
                };
                params.transfer = tr;
                params.v0 = v0;
                params.channels = self.header.channels as u32;
                params.key0 = r.keys[0] as u32;
                params.key1 = r.keys[1] as u32;
                params.alpha = alpha;
                params.blend = (state == FrameState::CatchingUp || hold_first) as u32;
                if hold_first {
                    params.alpha = 1e-3;
                }
                eval = Some((s, params, hold_first));
            }
        }
        self.last_shown = shown;
        let record = self.record(t0, wall, shown, state, alpha, seg, u, uploaded, decode_ns);
        Frame { record, eval }
    }

    #[allow(clippy::too_many_arguments)]
    fn record(
        &mut self,
        t0: Instant,
        wall: MediaTime,
        shown: MediaTime,
        state: FrameState,
        alpha: f32,
        segment: usize,
        u: f64,
        uploaded: u64,
        decode_ns: u64,
    ) -> FrameRecord {
        let read = self.totals.bytes_read - self.read_reported;
        self.read_reported = self.totals.bytes_read;
        let record = FrameRecord {
            index: self.frame,
            clock_ns: self.ticks,
            target: frames_f64(wall),
            shown: frames_f64(shown),
            drift: frames_f64(wall) - frames_f64(shown),
            state,
            bytes_read: read,
            bytes_uploaded: uploaded,
            decode_ns,
            render_ns: t0.elapsed().as_nanos() as u64,
            alpha,
            segment,
            u,
        };
        self.frame += 1;
        self.totals.frames += 1;
        self.totals.bytes_uploaded += uploaded;
        self.totals.decode_ns += decode_ns;
        record
    }

    /// Restarts reading at the last intra keyframe at or before media time `pos` (absolute,
    /// not wrapped): used when the display is so far behind that reading on would only
    /// deliver the past, and by [`Player::set_time`].
    fn seek(&mut self, pos: MediaTime) {
        let n = self.n_frames();
        let pass = (pos >> 32) / n;
        let f = ((pos >> 32) % n) as u32;
        let (keys, boundaries, entries) = match &self.pipeline {
            Pipeline::Inline { decoder, .. } => (
                decoder.layout().keyframes.clone(),
                decoder.layout().boundaries.clone(),
                decoder.entries().to_vec(),
            ),
            Pipeline::Threaded { .. } => (
                self.layout.keyframes.clone(),
                self.layout.boundaries.clone(),
                self.entries.clone(),
            ),
        };
        let s = boundaries
            .partition_point(|&b| b <= f)
            .saturating_sub(1)
            .min(boundaries.len().saturating_sub(2));
        let k = (0..=s.min(keys.len() - 1))
            .rev()
            .find(|&k| entries[keys[k]].is_intra())
            .unwrap_or(0);
        let first = (self.header.looping && k > 0).then_some(keys[0]);
        self.generation = self.generation.wrapping_add(1);
        if let Some(b) = self.incoming.take() {
            self.give_back(b);
        }
        self.slots = [None, None];
        self.shown_slot = None;
        self.key_slots = [None; KEY_SLOTS];
        match &mut self.pipeline {
            Pipeline::Inline {
                reader,
                decoder,
                pool,
                ready,
                ..
            } => {
                reader.restart(keys[k], pass as u32, first, self.ticks);
                decoder.reset();
                pool.append(ready);
            }
            Pipeline::Threaded { seek, threads, .. } => {
                let _ = seek.send((keys[k], pass as u32, first));
                unpark_reader(threads);
            }
        }
        self.totals.seeks += 1;
    }

    /// Jumps playback to `ticks` ns (of the playback clock).
    pub fn set_time(&mut self, ticks: u64) {
        self.ticks = ticks;
        self.paused = 0;
        self.startup = 0;
        let pos = ticks_to_media(ticks, self.header.rate_num, self.header.rate_den);
        self.seek(pos);
    }

    /// Stops the reader and decoder threads and waits for them (at most `deadline`).
    pub fn stop(&mut self, deadline: Duration) -> Result<(), PlayerError> {
        if let Pipeline::Threaded { stop, threads, .. } = &mut self.pipeline {
            stop.store(true, Ordering::SeqCst);
            threads.iter().for_each(|th| th.thread().unpark());
            let t = Instant::now();
            for th in threads.drain(..) {
                while !th.is_finished() {
                    if t.elapsed() > deadline {
                        return Err(PlayerError::Thread(format!(
                            "thread {} did not stop within {deadline:?}",
                            th.thread().name().unwrap_or("?")
                        )));
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                th.join()
                    .map_err(|_| PlayerError::Thread("a player thread panicked".into()))?;
            }
        }
        Ok(())
    }
}

impl<R: Read + Seek + Send + 'static> Drop for Player<R> {
    fn drop(&mut self) {
        let _ = self.stop(Duration::from_secs(10));
    }
}

/// Wakes the reader (the pipeline's first thread) to read a control message now: it may
/// be parked waiting for room in the ring.
fn unpark_reader(threads: &[JoinHandle<()>]) {
    if let Some(reader) = threads.first() {
        reader.thread().unpark();
    }
}

/// A thread to wake, once it exists.
type Waker = Arc<std::sync::OnceLock<std::thread::Thread>>;

fn wake(w: &Waker) {
    if let Some(t) = w.get() {
        t.unpark();
    }
}

/// Longest park while waiting on the ring: bounds a missed wake-up (there should be none:
/// an unpark before the park makes it return at once).
const PARK: Duration = Duration::from_millis(20);
/// How often a thread blocked on a channel looks at the stop flag.
const STOP_CHECK: Duration = Duration::from_millis(50);

#[allow(clippy::too_many_arguments)]
fn reader_loop<R: Read + Seek>(
    core: &mut ReaderCore<R>,
    mut prod: HeapProd<u8>,
    clock: &dyn Clock,
    stop: &AtomicBool,
    bytes_read: &AtomicU64,
    seek: &Receiver<(usize, u32, Option<usize>)>,
    throttle: &Receiver<Throttle>,
    wake_decoder: &Waker,
) {
    let give_up = || stop.load(Ordering::Relaxed) || !seek.is_empty();
    while !stop.load(Ordering::Relaxed) {
        while let Ok((pos, pass, first)) = seek.try_recv() {
            core.restart(pos, pass, first, clock.now_ns());
        }
        while let Ok(t) = throttle.try_recv() {
            core.throttle = t;
        }
        core.prepare(clock.now_ns());
        let Some(arrival) = core.next_arrival() else {
            // Finished a file that does not loop.
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        if !clock.sleep_until(arrival, &give_up) {
            continue;
        }
        // Wait for room in the ring: the decoder wakes this thread when it takes a chunk
        // out (the timeout only bounds a missed wake-up).
        while !core.deliver(clock.now_ns(), &mut prod) {
            if give_up() {
                break;
            }
            std::thread::park_timeout(PARK);
        }
        wake(wake_decoder);
        bytes_read.store(core.bytes_read, Ordering::Relaxed);
    }
}

fn decoder_loop(
    core: &mut DecoderCore,
    mut cons: HeapCons<u8>,
    free: Receiver<Box<SegmentData>>,
    ready: Sender<Box<SegmentData>>,
    errors: Sender<String>,
    stop: &AtomicBool,
    wake_reader: &Waker,
) {
    let mut msg = Vec::with_capacity(1 << 20);
    let mut generation = 0;
    // A box whose segment failed to decode: used again before asking for another.
    let mut spare: Option<Box<SegmentData>> = None;
    while !stop.load(Ordering::Relaxed) {
        // An empty ring: the reader wakes this thread when a chunk goes in. (Polling it
        // every 0.5 ms woke this thread ~9× as often at 1.2× the mean rate.)
        let Some(m) = pop_message(&mut cons, &mut msg) else {
            std::thread::park_timeout(PARK);
            continue;
        };
        wake(wake_reader);
        if m.generation != generation {
            generation = m.generation;
            core.reset();
        }
        match core.take(m.chunk as usize, m.ok.then_some(&msg[..])) {
            Event::Ready(s) => {
                // A free staging buffer: the render thread has uploaded one.
                let mut b = loop {
                    if let Some(b) = spare.take() {
                        break b;
                    }
                    match free.recv_timeout(STOP_CHECK) {
                        Ok(b) => break b,
                        Err(_) if stop.load(Ordering::Relaxed) => return,
                        Err(_) => {}
                    }
                };
                match core.fill(s, m.generation, m.pass, &mut b) {
                    Ok(()) => {
                        let mut b = Some(b);
                        while let Some(x) = b.take() {
                            match ready.send_timeout(x, STOP_CHECK) {
                                Ok(()) => {}
                                Err(crossbeam_channel::SendTimeoutError::Timeout(x)) => {
                                    if stop.load(Ordering::Relaxed) {
                                        return;
                                    }
                                    b = Some(x);
                                }
                                Err(_) => return,
                            }
                        }
                    }
                    Err(e) => {
                        let _ = errors.try_send(e);
                        spare = Some(b);
                    }
                }
            }
            Event::Damaged(e) => {
                let _ = errors.try_send(e);
            }
            Event::Nothing => {}
        }
    }
}

/// Returns the ring's media time of one frame, for the stats (media frames per ns).
pub fn frame_ns(h: &Header) -> u64 {
    media_to_ticks(ONE_FRAME, h.rate_num, h.rate_den)
}
