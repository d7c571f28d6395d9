//! The player: the render-thread state machine that decides what each displayed frame
//! shows under the stall policy, the GPU work it records, seeking, and the per-frame
//! record of what it did. The reader and decoder behind it are in `pipeline.rs`; the
//! slot bookkeeping in `slots.rs`.

use std::io::{Read, Seek};
use std::time::{Duration, Instant};

use vbim_format::index::Layout;
use vbim_format::{Header, IndexEntry, Reader, Transfer};

use crate::config::{PlayerConfig, Policy};
use crate::decoder::SegmentData;
use crate::display::{Display, Step};
use crate::gpu::{min_array_layers, planned_texture_bytes, Gpu, Op, Params};
use crate::pipeline::Pipeline;
use crate::record::{Frame, FrameRecord, FrameState, Totals};
use crate::slots::{KeySlots, Resident, MAX_BUBBLE_PLANES};
use crate::throttle::Throttle;
use crate::time::{frames_f64, ticks_to_media, MediaTime, ONE_FRAME};

mod decoding;
mod join;
use crate::PlayerError;
use decoding::Decoding;

/// After a re-synchronisation, how long to let the reader catch up before another.
const SEEK_COOLDOWN_NS: u64 = 2_000_000_000;

/// A `.vbim` stream playing into a GPU texture. See the crate's documentation.
pub struct Player<R: Read + Seek + Send + 'static> {
    header: Header,
    layout: Layout,
    entries: Vec<IndexEntry>,
    gpu: Gpu,
    pipeline: Pipeline<R>,
    /// The box received but not yet decoded on the GPU.
    incoming: Option<Box<SegmentData>>,
    /// The segment being decoded, a slice at a time.
    decoding: Option<Decoding>,
    /// The decode ops this frame records, and the box its upload needs.
    frame_ops: Vec<Op>,
    frame_box: Option<Box<SegmentData>>,
    /// A retired decode's op and step lists, reused by the next.
    spare: (Vec<Op>, Vec<crate::decoder::KeyStep>),
    /// The per-frame decode budget, blocks, and the work this frame records.
    budget: Option<u64>,
    /// The change (code domain, Σ over planes) a tile of the lightmap may lag by
    /// (`PlayerConfig::reuse_share` of the protocol's bound).
    reuse: f32,
    frame_work: u64,
    /// Which keyframes the GPU holds.
    keys: KeySlots,
    /// The segment the GPU can evaluate (its bubbles and keyframes are resident).
    resident: Option<Resident>,
    /// The end of the last segment whose keyframes the GPU built (shown or dropped): how
    /// far the data has come.
    known_end: MediaTime,
    /// The parameters of the last reconstruction, while the GPU's data is unchanged.
    last_eval: Option<Params>,
    /// The display's clock and stall policy.
    display: Display,
    /// Playback clock, ns.
    ticks: u64,
    /// Seek generation: boxes decoded before the last seek are not shown.
    generation: u32,
    /// Clock at the last re-synchronisation.
    last_seek: u64,
    /// Bytes read already reported in a frame record.
    read_reported: u64,
    frame: u64,
    totals: Totals,
    ring_bytes: usize,
    /// Buffering before the first frame, ns.
    preroll: u64,
    /// The reader's bandwidth cap, bytes/s (where a join can start: `join.rs`).
    read_rate: Option<u64>,
}

fn ring_capacity(h: &Header, entries: &[IndexEntry], cfg: &PlayerConfig) -> usize {
    let largest =
        entries.iter().map(|e| e.length).max().unwrap_or(0) as usize + crate::reader::MSG_HEADER;
    let model = match cfg.throttle.rate {
        Some(r) => h
            .read_ahead_at(r)
            .map(|p| p.bytes)
            .unwrap_or_else(|| h.read_ahead.iter().map(|p| p.bytes).max().unwrap_or(0)),
        None => h.read_ahead.iter().map(|p| p.bytes).max().unwrap_or(0),
    };
    // Never more than the whole file and its message headers: a read-ahead (stated by the
    // header, or asked for) beyond that buys nothing, and a hostile header's 2^62 bytes
    // would abort the allocation.
    let whole = entries
        .iter()
        .map(|e| e.length.saturating_add(crate::reader::MSG_HEADER as u64))
        .fold(0u64, u64::saturating_add);
    let ring = cfg.ring_bytes.map_or(model, |r| r as u64).min(whole) as usize;
    ring.max(largest) + crate::reader::MSG_HEADER * 4
}

/// Buffering before the first frame, ns: the header's pre-roll at the reader's rate (none
/// when unthrottled) and the caller's margin. Never longer than reading the whole file at
/// that rate, which is all a pre-roll can be for.
fn preroll_ns(h: &Header, cfg: &PlayerConfig) -> u64 {
    let model = cfg.preroll_ns.unwrap_or_else(|| {
        cfg.throttle.rate.map_or(0, |r| {
            let stated = h.read_ahead_at(r).map_or_else(
                || h.read_ahead.iter().map(|p| p.preroll_ns).max().unwrap_or(0),
                |p| p.preroll_ns,
            );
            let whole_file = (h.file_size as u128 * 1_000_000_000 / r.max(1) as u128)
                .min(u64::MAX as u128) as u64;
            stated.min(whole_file)
        })
    });
    model.saturating_add(cfg.preroll_margin_ns)
}

/// What a stream can make the player hold, checked before any of it exists: the textures,
/// exactly (the dense plane the parse fills among them); the ring; and the decoder's
/// payloads, boxes, scanned keyframes and the stream buffer, each at most a few times the
/// largest payload (which the file's own chunk sizes bound: `limits::MAX_EXPANSION`), and
/// in version 2 what decoding a section holds.
/// Array textures have at least `min_layers` layers; `lanes`: the GPU decodes a version 2
/// file's sections as coded ([`DecodeShape::lanes`](crate::DecodeShape::lanes)).
pub(crate) fn memory_needed(
    header: &Header,
    entries: &[IndexEntry],
    ring_bytes: usize,
    (min_layers, lanes): (u32, bool),
) -> u64 {
    let (pw, ph) = vbim_format::chunk::padded_size(header);
    let textures = planned_texture_bytes(
        (header.width, header.height),
        [pw as u32, ph as u32],
        (header.max_degree as u32, header.tile_size as u32),
        header.channels as u32,
        min_layers,
    );
    let payload = vbim_format::largest_payload(header, entries);
    // The entry points the scan adds inside long runs of equal DC (16 bytes per
    // `FILL_BLOCKS` blocks of a plane: the payload does not bound them), for every plane
    // of the boxes in flight and their staging copies.
    let blocks = (pw as u64 / 8) * (ph as u64 / 8);
    let fill_entries = 48
        * header.channels as u64
        * header.max_degree.max(1) as u64
        * (blocks / vbim_format::chunk::FILL_BLOCKS + 1)
        * 16;
    // A version 2 file's sections: decoded to pairs on the decoder thread where its
    // planes are larger than the dense plane, else the GPU's scratch for decoding them.
    let sections = vbim_format::section_memory(header, entries);
    let lanes = match lanes {
        true => crate::gpu::lanes_bytes(header),
        false => 0,
    };
    textures + ring_bytes as u64 + 8 * payload + fill_entries + sections + lanes
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
            return Err(PlayerError::NothingToPlay);
        }
        let ring_bytes = ring_capacity(&header, &entries, &cfg);
        let shape = crate::shape::resolved(&cfg, device);
        let preroll = preroll_ns(&header, &cfg);
        if header.max_degree as usize - 1 > MAX_BUBBLE_PLANES / 3 {
            return Err(PlayerError::Format(vbim_format::FormatError::Invalid(
                format!(
                    "degree {} is beyond the player's {}",
                    header.max_degree,
                    MAX_BUBBLE_PLANES / 3 + 1
                ),
            )));
        }
        let (pw, ph) = vbim_format::chunk::padded_size(&header);
        let max_side = device.limits().max_texture_dimension_2d;
        if pw.max(ph) > max_side as usize {
            return Err(PlayerError::TooLarge {
                width: header.width,
                height: header.height,
                coded: [pw, ph],
                max_side,
            });
        }
        cfg.limits.check(
            &format!(
                "playing a {}×{} stream of {} channel(s), degree ≤ {}",
                header.width, header.height, header.channels, header.max_degree
            ),
            memory_needed(
                &header,
                &entries,
                ring_bytes,
                (min_array_layers(device), shape.lanes),
            ),
        )?;
        let mut gpu = Gpu::for_stream(device, queue, &header, shape);
        gpu.reuse_probe = cfg.reuse_probe;
        let pipeline = Pipeline::start(device, src, &header, &layout, &entries, &cfg, ring_bytes)?;
        let display = Display::new(cfg.policy, cfg.catch_up_ns, preroll);
        let reuse = reuse_threshold(cfg.reuse_share, header.transfer);
        Ok(Player {
            header,
            layout,
            entries,
            gpu,
            pipeline,
            incoming: None,
            decoding: None,
            frame_ops: Vec::new(),
            frame_box: None,
            spare: (Vec::new(), Vec::new()),
            budget: cfg.decode_budget,
            reuse,
            frame_work: 0,
            keys: KeySlots::default(),
            resident: None,
            known_end: 0,
            last_eval: None,
            display,
            ticks: 0,
            generation: 0,
            last_seek: 0,
            read_reported: 0,
            frame: 0,
            totals: Totals::default(),
            ring_bytes,
            preroll,
            read_rate: cfg.throttle.rate,
        })
    }

    /// The stream's header.
    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The lightmap (linear RGB, Rgba16Float) the renderer samples.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.gpu.display_view
    }
    /// Reconstructs into `texture`, a texture of the caller's, from the next frame on,
    /// instead of the player's own lightmap ([`Player::view`] then stops changing); `None`
    /// goes back to the player's own. For an engine whose materials keep the texture they
    /// were built with. The texture must be `width × height`, 2D, `Rgba16Float`, with
    /// `STORAGE_BINDING | TEXTURE_BINDING` usage (the player reads it to keep the image on
    /// screen for the catch-up blend; [`Player::read_display`] also needs `COPY_SRC`); the
    /// player keeps a clone of the handle while it writes it.
    pub fn set_output(&mut self, texture: Option<&wgpu::Texture>) -> Result<(), PlayerError> {
        self.last_eval = None;
        self.gpu.set_output(texture).map_err(PlayerError::Output)
    }

    /// Reads the lightmap back to the CPU: RGBA, f32, row by row. Blocks until the GPU is
    /// done; for tests, checks and captures, never per frame.
    pub fn read_display(&self) -> Vec<f32> {
        self.gpu.read_display()
    }

    /// Bytes of GPU memory the player holds: its textures (the head keyframe and the one
    /// before it, the bubble planes, the lightmap and its held copy) and its buffers (the coefficients of
    /// the segment being decoded, the passes' parameters). The runtime's budget is stated
    /// in these bytes per texel of the lightmap.
    pub fn gpu_bytes(&self) -> u64 {
        self.gpu.bytes()
    }

    /// Blocks until the GPU has finished what was submitted (to time the GPU's share).
    pub fn wait_for_gpu(&self) {
        self.gpu.wait();
    }

    /// Puts GPU timestamps between the passes of every frame from now on, where the
    /// device has them inside passes ([`bench::timing_device`]); returns whether it does.
    /// Each frame's are read with [`Player::pass_times`] once it is done. For `vbim bench
    /// render --passes`; the frame's GPU time then includes the marks' own.
    ///
    /// [`bench::timing_device`]: crate::bench::timing_device
    #[cfg(feature = "bench")]
    pub fn time_passes(&mut self) -> bool {
        self.gpu.time_passes()
    }

    /// The GPU time of each pass of the frames recorded since the last call (ns, in the
    /// order recorded: the decode's by kind, then `reconstruct`), once they are done
    /// ([`Player::wait_for_gpu`]); empty unless [`Player::time_passes`].
    #[cfg(feature = "bench")]
    pub fn pass_times(&self) -> Vec<(&'static str, f64)> {
        self.gpu.read_marks()
    }

    /// Running totals since the player was opened.
    pub fn totals(&self) -> &Totals {
        &self.totals
    }
    /// Buffering before the first frame, ns (the pre-roll and its margin).
    pub fn preroll_ns(&self) -> u64 {
        self.preroll
    }
    /// The ring's capacity in bytes.
    pub fn ring_bytes(&self) -> usize {
        self.ring_bytes
    }
    /// Playback clock, ns.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
    /// The stall policy in force.
    pub fn policy(&self) -> Policy {
        self.display.policy()
    }
    /// Changes the stall policy from the next frame on.
    pub fn set_policy(&mut self, p: Policy) {
        self.display.set_policy(p);
    }

    /// Changes the reader's bandwidth cap and stalls from now on (inline mode: at once;
    /// threaded mode: at the reader's next chunk).
    pub fn set_throttle(&mut self, t: Throttle) {
        self.read_rate = t.rate;
        self.pipeline.set_throttle(t);
    }

    fn n_frames(&self) -> u64 {
        self.header.frame_count as u64
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

    /// Records the GPU work of a planned frame: the decode of a newly arrived segment, and
    /// the reconstruction, in one submission of its own.
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
    /// frame. Submit `encoder` before the next frame: it must be the next submission on
    /// the player's queue, because the frame's coefficients and parameters go through
    /// `Queue::write_buffer`, which lands at the next submission. Then call [`submitted`].
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
        #[cfg(feature = "bench")]
        self.gpu.mark_start(encoder);
        if !self.frame_ops.is_empty() {
            self.gpu
                .record(encoder, &self.frame_ops, self.frame_box.as_deref());
            self.frame_ops.clear();
        }
        // Its bytes are with wgpu now (`write_buffer` copies them, the copy from staging
        // is recorded): the box goes back.
        if let Some(b) = self.frame_box.take() {
            self.pipeline.give_back(b);
        }
        if let Some((params, hold_first)) = &frame.eval {
            // The same parameters over the same resident data give the same image (a
            // hold, a pause, the Wait policy): the texture already holds it.
            let same = self.last_eval.as_ref().is_some_and(|p| {
                bytemuck::bytes_of(p) == bytemuck::bytes_of(params) && !*hold_first
            });
            if same {
                self.totals.frames_unchanged += 1;
            } else {
                let fresh = self.last_eval.is_none();
                self.gpu.reconstruct(encoder, params, *hold_first, fresh);
                self.last_eval = Some(*params);
            }
        }
    }

    /// Tells the player that the encoder of its last [`Player::advance_into`] was
    /// submitted. The player needs nothing after a submission since it decodes on the GPU
    /// (its uploads go through `Queue::write_buffer`); renderers written for earlier
    /// versions, which had to call it, keep working unchanged.
    pub fn submitted(&mut self) {}

    /// Starts decoding the segment the decoder thread sent, if none is decoding and one
    /// came (of this seek generation: `pump` gives back the others, and a seek gives back
    /// what was waiting); returns the bytes it uploads.
    fn start_incoming(&mut self, pos: MediaTime, n: MediaTime) -> u64 {
        if self.decoding.is_some() {
            return 0;
        }
        match self.incoming.take() {
            Some(b) => self.start_decode(b, pos, n),
            None => 0,
        }
    }

    /// The CPU side of a frame, allocation-free: takes what the reader and decoder
    /// produced, decides what is shown under the policy, and computes the shader's weights.
    pub fn plan(&mut self, dt: u64) -> Frame {
        let t0 = Instant::now();
        self.ticks += dt;
        let cpu = self.pipeline.pump(
            self.ticks,
            self.generation,
            &mut self.incoming,
            &mut self.totals,
        );
        let rate = (self.header.rate_num, self.header.rate_den);
        let n = self.n_frames() << 32;
        let (wall, mut pos) = self.display.clock(self.ticks, rate);
        if !self.header.looping {
            pos = pos.min(n - ONE_FRAME);
        }
        // Start decoding an arrived segment into what is not on screen (one at a time),
        // then record this frame's share of the decode in flight.
        let mut uploaded = self.start_incoming(pos, n);
        let per_frame = ticks_to_media(dt, rate.0, rate.1);
        let was_decoding = self.decoding.is_some();
        self.frame_work = self.step_decode(pos, per_frame, n);
        if was_decoding && self.decoding.is_none() && self.frame_ops.is_empty() {
            // The segment decoded ahead went on screen this frame, which frees what the
            // one before it held: the next decode starts now, not a frame later (a
            // 10-frame segment's next decode then has all its frames, not the 7 its
            // spread had left after the start's frame and the margin).
            uploaded += self.start_incoming(pos, n);
            self.frame_work = self.step_decode(pos, per_frame, n);
        }
        let missing = !self.resident.is_some_and(|r| r.start <= pos && pos < r.end);
        if missing && self.ticks.saturating_sub(self.last_seek) > SEEK_COOLDOWN_NS {
            // So far behind that reading on would only deliver the past: re-synchronise
            // at the last intra keyframe before the target.
            if pos.saturating_sub(self.known_end) > (n / 2).max(ONE_FRAME) {
                self.last_seek = self.ticks;
                self.seek(pos);
            }
        }
        // Data late: hold the end of what is on screen (its closing keyframe), or its start.
        let held = missing.then(|| {
            self.resident.map_or(self.display.last_shown(), |r| {
                if pos >= r.end {
                    r.end - 1
                } else {
                    r.start
                }
            })
        });
        let (state, shown, alpha, hold_first) = match self.display.step(self.ticks, pos, held, rate)
        {
            Step::Preroll => {
                // Target and shown are both the start: pre-roll is not drift.
                let record = self.record(t0, 0, 0, FrameState::Waiting, 1.0, 0, 0.0, uploaded, cpu);
                return Frame { record, eval: None };
            }
            Step::Show {
                state,
                shown,
                alpha,
                hold_first,
                new_stall,
            } => {
                self.totals.stalls += new_stall as u64;
                (state, shown, alpha, hold_first)
            }
        };
        // Evaluate the resident segment at the (clamped) time. With none (its keyframes
        // went to a dropped segment's), the display keeps the image it has.
        let (mut seg, mut u) = (0, 0.0);
        let mut eval = None;
        if let Some(r) = self.resident {
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
            params.reuse = self.reuse;
            let ch = self.header.channels as u32;
            params.channels = ch;
            // K_s from its slot; K_{s+1} from the head until the next decode packs it.
            let packed = self.keys.slot_of(r.keys[1]);
            params.keys = [r.slot0 * ch, packed.unwrap_or(0) * ch];
            params.head_f32 = packed.is_none() as u32;
            params.set_base = r.set * self.gpu.set_layers;
            params.steps = r.steps;
            params.alpha = alpha;
            params.blend = (state == FrameState::CatchingUp || hold_first) as u32;
            if hold_first {
                params.alpha = 1e-3;
            }
            eval = Some((params, hold_first));
        }
        let record = self.record(t0, wall, shown, state, alpha, seg, u, uploaded, cpu);
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
        [read_ns, decode_ns]: [u64; 2],
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
            read_ns,
            decode_ns,
            render_ns: t0.elapsed().as_nanos() as u64,
            alpha,
            segment,
            u,
            decode_work: self.frame_work,
        };
        self.totals.decode_work += self.frame_work;
        self.totals.decode_work_max = self.totals.decode_work_max.max(self.frame_work);
        self.frame += 1;
        self.totals.frames += 1;
        self.totals.bytes_uploaded += uploaded;
        self.totals.read_ns += read_ns;
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
        let (keys, boundaries) = (&self.layout.keyframes, &self.layout.boundaries);
        let s = boundaries
            .partition_point(|&b| b <= f)
            .saturating_sub(1)
            .min(boundaries.len().saturating_sub(2));
        let k = (0..=s.min(keys.len() - 1))
            .rev()
            .find(|&k| self.entries[keys[k]].is_intra())
            .unwrap_or(0);
        let restart = (
            keys[k],
            pass as u32,
            (self.header.looping && k > 0).then_some(keys[0]),
        );
        self.generation = self.generation.wrapping_add(1);
        if let Some(b) = self.incoming.take() {
            self.pipeline.give_back(b);
        }
        if let Some(d) = self.decoding.take() {
            self.retire(d);
        }
        // (This frame's ops, if any, were chosen before the seek: they still record, on
        // buffers nothing else reads before the next decode's upload.)
        self.resident = None;
        // The data restarts for `pos`: measure how far behind it falls from there (from 0,
        // a seek past half the day looked far behind before any data could come, and a
        // capped reader was restarted every cooldown, never catching up).
        self.known_end = pos;
        self.keys.clear();
        self.pipeline
            .restart(restart, (s, self.generation), self.ticks);
        self.totals.seeks += 1;
    }

    /// Jumps playback to `ticks` ns (of the playback clock).
    pub fn set_time(&mut self, ticks: u64) {
        self.ticks = ticks;
        // A jump is a re-synchronisation: the next frames, whose data is still coming,
        // must not re-synchronise again (with nothing built yet they look far behind).
        self.last_seek = ticks;
        let pos = ticks_to_media(ticks, self.header.rate_num, self.header.rate_den);
        self.display.restart_clock(pos);
        self.seek(pos);
    }

    /// Stops the reader and decoder threads and waits for them (at most `deadline`).
    pub fn stop(&mut self, deadline: Duration) -> Result<(), PlayerError> {
        self.pipeline.stop(deadline)
    }
}

// An engine keeps its player in a resource its render thread uses (Bevy's render world
// needs `Send`): a change that made the player `!Send` must fail to compile here.
const _: () = {
    const fn assert_send<T: Send>() {}
    assert_send::<Player<std::fs::File>>();
    assert_send::<Player<std::io::Cursor<Vec<u8>>>>();
};

impl<R: Read + Seek + Send + 'static> Drop for Player<R> {
    fn drop(&mut self) {
        let _ = self.stop(Duration::from_secs(10));
    }
}

/// The change of Σ over planes of |c| (the code domain the reconstruction sums in) that
/// keeps every displayed channel within `share` of the protocol's bound on the GPU
/// against the reference: 0.5/255 of a code value for sRGB; for the log toe
/// v = v0 (2^c − 1), whose slope is ln 2 · (v + v0), 2^-10 of v above 10^-3 and 10^-6
/// below it (both at most 2^-10 · ln 2 · (10^-3 + v0) / 10^-3 per unit of c, the worst
/// case at v = 10^-3). YCoCg → RGB adds the planes' changes at most. 0 (or NaN): every
/// tile every frame; infinity: a tile only when the keyframes or the output change.
pub(crate) fn reuse_threshold(share: f32, transfer: Transfer) -> f32 {
    if share.is_nan() || share <= 0.0 {
        return 0.0;
    }
    match transfer {
        Transfer::Srgb => share * 0.5 / 255.0,
        Transfer::LogToe { v0 } => {
            share * (2f32.powi(-10) / (std::f32::consts::LN_2 * (1.0 + 1000.0 * v0.max(0.0))))
        }
    }
}
