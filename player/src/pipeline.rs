//! The pipeline behind the render thread: a reader and a decoder joined by a ring of
//! compressed bytes, and three boxes (`BOXES`) of scanned coefficient streams that travel decoder → render
//! thread → decoder.
//! They run on threads of their own (paper 001's figure 13), or are stepped inline inside
//! `advance` so that simulated time is deterministic.

use std::io::{Read, Seek};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{bounded, Receiver, Sender, TryRecvError};
use ringbuf::traits::Split;
use ringbuf::{HeapCons, HeapProd, HeapRb};
use vbim_format::index::Layout;
use vbim_format::{Header, IndexEntry};

use crate::clock::Clock;
use crate::config::PlayerConfig;
use crate::cpu_time::thread_cpu_ns;
use crate::decoder::{DecoderCore, Event, SegmentData};
use crate::reader::{pop_message, ReaderCore};
use crate::record::Totals;
use crate::throttle::Throttle;
use crate::PlayerError;

/// Where reading restarts after a seek: chunk, pass, and the first keyframe's chunk when
/// the loop's start must be read again first.
type Restart = (usize, u32, Option<usize>);

/// The segment a seek is for, with the seek generation it belongs to (generation << 32 |
/// segment): the decoder sends no box for the segments before it, only their keyframes
/// in the first box's chain.
type SeekTarget = Arc<AtomicU64>;

/// Boxes of parsed segments between the decoder and the render thread: one waiting for
/// its time on the render thread, one ready behind it, one being filled. (The segment on
/// screen needs none: its data is on the GPU.) Two boxes held one decoded segment less
/// ahead and dropped half again as many segments after a stall.
const BOXES: usize = 3;

/// The reader and decoder, and the way boxes go back to the decoder.
pub(crate) struct Pipeline<R> {
    /// Boxes going back to the decoder after upload.
    recycle: Sender<Box<SegmentData>>,
    mode: Mode<R>,
}

// Staging buffers travel as the same boxes through channels and these pools.
#[allow(clippy::vec_box)]
enum Mode<R> {
    Threaded {
        stop: Arc<AtomicBool>,
        seek: Sender<Restart>,
        target: SeekTarget,
        throttle: Sender<Throttle>,
        threads: Vec<JoinHandle<()>>,
        ready: Receiver<Box<SegmentData>>,
        errors: Receiver<String>,
        bytes_read: Arc<AtomicU64>,
        read_seen: u64,
        /// Each thread's own CPU time so far (stored by the thread), and what was
        /// reported: reader, decoder.
        cpu: [Arc<AtomicU64>; 2],
        cpu_seen: [u64; 2],
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

impl<R: Read + Seek + Send + 'static> Pipeline<R> {
    /// Starts reading `src` into a ring of `ring_bytes`, with `BOXES` boxes for the decoder.
    pub fn start(
        device: &wgpu::Device,
        src: R,
        header: &Header,
        layout: &Layout,
        entries: &[IndexEntry],
        cfg: &PlayerConfig,
        ring_bytes: usize,
    ) -> Result<Self, PlayerError> {
        let (prod, cons) = HeapRb::<u8>::new(ring_bytes).split();
        let mut reader_core = ReaderCore::new(src, entries.to_vec(), header.looping, cfg.throttle);
        let mut decoder = DecoderCore::new(header.clone(), layout.clone(), entries.to_vec());
        decoder.set_lanes(crate::shape::resolved(cfg, device).lanes);
        decoder.stage_on(device.clone());
        let (recycle_tx, recycle_rx) = bounded::<Box<SegmentData>>(BOXES);
        for _ in 0..BOXES {
            recycle_tx
                .send(Box::new(SegmentData::new()))
                .expect("room for two");
        }
        let mode = if cfg.threaded {
            let stop = Arc::new(AtomicBool::new(false));
            let bytes_read = Arc::new(AtomicU64::new(0));
            let (ready_tx, ready_rx) = bounded::<Box<SegmentData>>(BOXES);
            let (err_tx, err_rx) = bounded::<String>(64);
            let (seek_tx, seek_rx) = bounded::<Restart>(16);
            let (throttle_tx, throttle_rx) = bounded::<Throttle>(16);
            let target = SeekTarget::default();
            let decoder_target = target.clone();
            let clock = cfg.clock.clone();
            let (s1, s2) = (stop.clone(), stop.clone());
            let br = bytes_read.clone();
            let cpu = [Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0))];
            let (reader_cpu, decoder_cpu) = (cpu[0].clone(), cpu[1].clone());
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
                        &reader_cpu,
                    )
                })
                .map_err(PlayerError::Thread)?;
            let mut dec = decoder;
            let decoder_thread = std::thread::Builder::new()
                .name("vbim-decoder".into())
                .spawn(move || {
                    decoder_loop(
                        &mut dec,
                        cons,
                        recycle_rx,
                        ready_tx,
                        err_tx,
                        &s2,
                        &wr,
                        &decoder_target,
                        &decoder_cpu,
                    )
                })
                .map_err(PlayerError::Thread)?;
            let _ = wake_reader.set(reader_thread.thread().clone());
            let _ = wake_decoder.set(decoder_thread.thread().clone());
            Mode::Threaded {
                stop,
                seek: seek_tx,
                target,
                throttle: throttle_tx,
                threads: vec![reader_thread, decoder_thread],
                ready: ready_rx,
                errors: err_rx,
                bytes_read,
                read_seen: 0,
                cpu,
                cpu_seen: [0; 2],
            }
        } else {
            let pool: Vec<Box<SegmentData>> = recycle_rx.try_iter().collect();
            reader_core.prepare();
            Mode::Inline {
                reader: Box::new(reader_core),
                prod,
                cons,
                decoder: Box::new(decoder),
                msg: Vec::with_capacity(1 << 20),
                ready: Vec::with_capacity(BOXES),
                pool,
                read_seen: 0,
            }
        };
        Ok(Pipeline {
            recycle: recycle_tx,
            mode,
        })
    }

    /// Moves the pipeline forward to playback time `now` (inline mode) and takes a decoded
    /// segment of seek generation `generation` into `incoming` if it is empty (never
    /// blocks); boxes decoded before the last seek go straight back to the decoder. Counts
    /// bytes read and damaged chunks into `totals`; returns the CPU time the reader and the
    /// decoder spent since the last call, ns, each on its own thread's clock (inline: the
    /// time this call spent in each).
    pub fn pump(
        &mut self,
        now: u64,
        generation: u32,
        incoming: &mut Option<Box<SegmentData>>,
        totals: &mut Totals,
    ) -> [u64; 2] {
        match &mut self.mode {
            Mode::Threaded {
                ready,
                errors,
                bytes_read,
                read_seen,
                cpu,
                cpu_seen,
                ..
            } => {
                while let Ok(e) = errors.try_recv() {
                    totals.damaged += 1;
                    totals.last_error = Some(e);
                }
                // Every stale box at once: dropping one a frame left a seek waiting a
                // frame for each segment that was decoded before it (a paused Bevy app on
                // lavapipe, a few frames a second, showed the sky a minute after the
                // lightmap).
                while incoming.is_none() {
                    match ready.try_recv() {
                        Ok(b) if b.generation != generation => {
                            let _ = self.recycle.try_send(b);
                        }
                        Ok(b) => *incoming = Some(b),
                        Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => break,
                    }
                }
                let r = bytes_read.load(Ordering::Relaxed);
                totals.bytes_read += r - *read_seen;
                *read_seen = r;
                std::array::from_fn(|i| {
                    let t = cpu[i].load(Ordering::Relaxed);
                    let d = t.saturating_sub(cpu_seen[i]);
                    cpu_seen[i] = cpu_seen[i].max(t);
                    d
                })
            }
            Mode::Inline {
                reader,
                prod,
                cons,
                decoder,
                msg,
                pool,
                ready,
                read_seen,
            } => {
                // At most two passes over the file per frame: a stream in which nothing can
                // be decoded (a damaged chain that never recovers) never fills a box, and an
                // unthrottled reader would otherwise wrap around it forever inside this one
                // call. A playable stream never needs as much: what the decoder takes before
                // every box is full, plus a ring no larger than the file.
                let mut budget = 2 * reader.chunk_count() + 4;
                let (mut read_ns, mut decode_ns) = (0, 0);
                loop {
                    let mut progress = false;
                    let t = thread_cpu_ns();
                    reader.prepare();
                    if budget > 0 && reader.deliver(now, prod) {
                        progress = true;
                        budget -= 1;
                    }
                    let t1 = thread_cpu_ns();
                    read_ns += t1 - t;
                    // Decode only while a box is free (the render thread returns
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
                                        totals.damaged += 1;
                                        totals.last_error = Some(e);
                                        pool.push(b);
                                    }
                                }
                            }
                            Event::Damaged(e) => {
                                totals.damaged += 1;
                                totals.last_error = Some(e);
                            }
                            Event::Nothing => {}
                        }
                    }
                    decode_ns += thread_cpu_ns() - t1;
                    if !progress {
                        break;
                    }
                }
                // (A restart puts the ready boxes back in the pool: none here is stale.)
                if incoming.is_none() && !ready.is_empty() {
                    *incoming = Some(ready.remove(0));
                }
                totals.bytes_read += reader.bytes_read - *read_seen;
                *read_seen = reader.bytes_read;
                [read_ns, decode_ns]
            }
        }
    }

    /// Gives a box back to the decoder.
    pub fn give_back(&mut self, b: Box<SegmentData>) {
        match &mut self.mode {
            Mode::Inline { pool, .. } => pool.push(b),
            Mode::Threaded { .. } => {
                let _ = self.recycle.try_send(b);
            }
        }
    }

    /// Changes the reader's bandwidth cap and stalls (inline mode: at once; threaded
    /// mode: at the reader's next chunk).
    pub fn set_throttle(&mut self, t: Throttle) {
        match &mut self.mode {
            Mode::Inline { reader, .. } => reader.throttle = t,
            Mode::Threaded {
                throttle, threads, ..
            } => {
                let _ = throttle.try_send(t);
                unpark_reader(threads);
            }
        }
    }

    /// Restarts reading at chunk `chunk` of pass `pass` (after reading chunk `first`
    /// when given) at playback time `now`, for segment `segment` in seek generation
    /// `generation`; what was decoded before is forgotten.
    pub fn restart(
        &mut self,
        (chunk, pass, first): Restart,
        (segment, generation): (usize, u32),
        now: u64,
    ) {
        match &mut self.mode {
            Mode::Inline {
                reader,
                decoder,
                pool,
                ready,
                ..
            } => {
                reader.restart(chunk, pass, first, now);
                decoder.reset_from(segment);
                pool.append(ready);
            }
            Mode::Threaded {
                seek,
                target,
                threads,
                ..
            } => {
                target.store(
                    (generation as u64) << 32 | segment as u32 as u64,
                    Ordering::Release,
                );
                let _ = seek.send((chunk, pass, first));
                unpark_reader(threads);
            }
        }
    }

    /// Stops the reader and decoder threads and waits for them (at most `deadline`).
    pub fn stop(&mut self, deadline: Duration) -> Result<(), PlayerError> {
        if let Mode::Threaded { stop, threads, .. } = &mut self.mode {
            stop.store(true, Ordering::SeqCst);
            threads.iter().for_each(|th| th.thread().unpark());
            let t = Instant::now();
            for th in threads.drain(..) {
                let name = th.thread().name().unwrap_or("?").to_string();
                while !th.is_finished() {
                    if t.elapsed() > deadline {
                        return Err(PlayerError::Stuck {
                            thread: name,
                            deadline,
                        });
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                th.join()
                    .map_err(|_| PlayerError::Panicked { thread: name })?;
            }
        }
        Ok(())
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
/// an unpark before the park makes it return at once: a stop unparks both threads, a seek
/// or a throttle change the reader, and the reader wakes the decoder with every chunk). At
/// 20 ms the reader, parked on a full ring, woke 50 times a second, most of its CPU time.
const PARK: Duration = Duration::from_millis(200);
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
    cpu: &AtomicU64,
) {
    let give_up = || stop.load(Ordering::Relaxed) || !seek.is_empty();
    while !stop.load(Ordering::Relaxed) {
        while let Ok((pos, pass, first)) = seek.try_recv() {
            core.restart(pos, pass, first, clock.now_ns());
        }
        while let Ok(t) = throttle.try_recv() {
            core.throttle = t;
        }
        core.prepare();
        let Some(arrival) = core.next_arrival() else {
            // Finished a file that does not loop: until a seek or a stop unparks it.
            std::thread::park_timeout(PARK);
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
        cpu.store(thread_cpu_ns(), Ordering::Relaxed);
    }
}

/// Whether a message of seek generation `generation` was read before the last seek.
fn stale(target: &SeekTarget, generation: u32) -> bool {
    (target.load(Ordering::Acquire) >> 32) as u32 != generation
}

#[allow(clippy::too_many_arguments)]
fn decoder_loop(
    core: &mut DecoderCore,
    mut cons: HeapCons<u8>,
    free: Receiver<Box<SegmentData>>,
    ready: Sender<Box<SegmentData>>,
    errors: Sender<String>,
    stop: &AtomicBool,
    wake_reader: &Waker,
    target: &SeekTarget,
    cpu: &AtomicU64,
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
        // What this thread has spent so far, up to the message before this one (stored
        // here rather than after the message: a `continue` or a blocked send skips the end
        // of the loop).
        cpu.store(thread_cpu_ns(), Ordering::Relaxed);
        if stale(target, m.generation) {
            // Read before the last seek (the seek's target is stored before the reader
            // hears of it): decoding it would hold a box the seek's segments need.
            continue;
        }
        if m.generation != generation {
            generation = m.generation;
            // The segment this generation's seek is for, if the seek was not overtaken.
            let t = target.load(Ordering::Acquire);
            let first = if (t >> 32) as u32 == generation {
                t as u32 as usize
            } else {
                0
            };
            core.reset_from(first);
        }
        match core.take(m.chunk as usize, m.ok.then_some(&msg[..])) {
            Event::Ready(s) => {
                // A free box: the render thread has uploaded one.
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
                if stale(target, m.generation) {
                    // A seek came while this thread waited for the box.
                    spare = Some(b);
                    continue;
                }
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
