//! The decoder: takes chunks from the ring, verifies them, decompresses and scans
//! keyframes and coefficients, and when a segment's keyframes, tile map
//! and coefficients are all there packs what the GPU needs for it into a box
//! ([`SegmentData`]): the keyframe steps that bring the GPU's resident keyframes to the
//! segment's K_s and K_{s+1}, and the segment's bubble planes: each plane's coefficient
//! stream as coded, with the entry points its scan found (`coded.rs`). The scan is where a
//! malformed stream is refused; parsing, dequantisation, the inverse DCT and predicted
//! keyframes are the GPU's.
//!
//! A damaged chunk (checksum mismatch, or the source failed) is reported and makes what
//! depends on it undecodable: a keyframe breaks the predicted chain until the next intra
//! keyframe, a tile map or coefficient chunk only its segment. Playback resumes with the
//! first segment whose parts are all good.

use crate::coded::{Coded, PlaneSpan, SectionSpan};
use crate::cpu_time::thread_cpu_ns;

use vbim_format::chunk::{self, Payload, TileMap};
use vbim_format::index::Layout;
use vbim_format::payload2::section_planes;
use vbim_format::plane2::Section;
use vbim_format::verify_chunk;
use vbim_format::{ChunkKind, Header, IndexEntry};

/// One keyframe for the GPU to build on its head keyframe: from zeros (intra) or onto the
/// keyframe before it, which the head holds (predicted).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KeyStep {
    /// The keyframe's number.
    pub number: usize,
    /// Coded on its own.
    pub intra: bool,
    /// Its first plane in `SegmentData::planes` (`channels` planes follow).
    pub plane: usize,
}

/// A segment ready for the GPU: the keyframe steps (in order; the last two built are
/// its K_s and K_{s+1}) and its bubble planes, as streams and entry points in `data`.
///
/// After the first segment, a box holds one step, K_{s+1}: the segment the decoder sent
/// before closed on K_s, which the GPU built then. After a seek, damage or a failed
/// segment it holds the chain from the last intra keyframe (the GPU cannot have it).
pub struct SegmentData {
    /// The seek generation it was decoded in: a box from before a seek is not shown.
    pub generation: u32,
    /// The loop pass of the reader that delivered it (0 for the first play-through).
    pub pass: u32,
    /// The segment's number.
    pub index: usize,
    /// Its first frame.
    pub start: u32,
    /// The frame after its last (its closing keyframe's frame).
    pub end: u32,
    /// Terms: 2 keyframes + bubbles (1 + the segment's highest degree).
    pub layers: usize,
    /// Keyframe numbers of K_s and K_{s+1}.
    pub keys: [usize; 2],
    /// Keyframes to build, in order.
    pub steps: Vec<KeyStep>,
    /// The segment's tile map or coefficients were damaged: the box carries its
    /// keyframes only, so that the GPU's chain goes on to the next segment.
    pub keys_only: bool,
    /// Every plane: the steps' keyframe planes, then bubble planes from `bubbles` on
    /// (term k ≥ 2, plane p at `bubbles + (k − 2)·channels + p`).
    pub(crate) planes: Vec<PlaneSpan>,
    /// A version 2 box's coefficient sections (its planes name theirs).
    pub(crate) sections: Vec<SectionSpan>,
    /// Where the bubble planes start in `planes`.
    pub bubbles: usize,
    pub(crate) data: Coded,
    /// The coefficients in a buffer of the GPU's (`data`'s layout), written by the thread
    /// that packed them, so that the render thread only records a copy; `None` where the
    /// decoder has no device (then the render thread uploads `data` itself).
    pub(crate) staged: Option<Staged>,
    /// CPU nanoseconds (the decoding thread's own clock) spent on this segment and the
    /// keyframes it carries.
    pub decode_ns: u64,
}

impl Default for SegmentData {
    fn default() -> Self {
        SegmentData::new()
    }
}

impl SegmentData {
    /// An empty box (its buffers grow to the largest segment and are then reused).
    pub fn new() -> SegmentData {
        SegmentData {
            generation: 0,
            pass: 0,
            index: 0,
            start: 0,
            end: 0,
            layers: 0,
            keys: [0, 0],
            steps: Vec::new(),
            keys_only: false,
            planes: Vec::new(),
            sections: Vec::new(),
            bubbles: 0,
            data: Coded::default(),
            staged: None,
            decode_ns: 0,
        }
    }

    /// Bytes the GPU upload of this box moves (streams, entry points, member spans).
    pub fn bytes(&self) -> u64 {
        self.staged.as_ref().map_or(self.data.bytes(), |s| s.bytes)
    }

    /// Moves the coded planes into a staging buffer of `device`'s, and frees their CPU
    /// copy.
    fn stage(&mut self, device: &wgpu::Device) {
        let bytes = self.data.bytes();
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim segment coefficients"),
            size: bytes.max(wgpu::COPY_BUFFER_ALIGNMENT),
            usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        });
        buffer
            .slice(..bytes)
            .get_mapped_range_mut()
            .slice(..)
            .copy_from_slice(bytemuck::cast_slice(&self.data.words));
        buffer.unmap();
        self.staged = Some(Staged { buffer, bytes });
        self.data.release();
    }

    /// Of its version 2 planes decoded as coded: the sum of each plane's longest lane and
    /// the lanes' words in all (16-bit words).
    #[cfg_attr(not(feature = "bench"), allow(dead_code))]
    pub fn lane_words(&self) -> (u64, u64) {
        let lanes = self.planes.iter().filter_map(|p| p.lanes);
        lanes.fold((0, 0), |(l, w), p| {
            (l + p.longest as u64, w + p.words as u64)
        })
    }

    /// Number of planes (keyframe and bubble) the box holds.
    #[cfg_attr(not(feature = "bench"), allow(dead_code))]
    pub fn plane_count(&self) -> usize {
        self.planes.len()
    }
}

/// A box's coefficients in a GPU buffer (`MAP_WRITE | COPY_SRC`), ready to be copied into
/// the decode pass's storage buffer.
pub(crate) struct Staged {
    pub buffer: wgpu::Buffer,
    /// Bytes in all (a whole number of words).
    pub bytes: u64,
}

/// What the decoder made of one chunk.
pub enum Event {
    /// The chunk was taken; nothing can be decoded yet.
    Nothing,
    /// Segment `index` can be decoded now (call [`DecoderCore::fill`]).
    Ready(usize),
    /// A chunk was damaged: a message naming it.
    Damaged(String),
}

/// A keyframe the decoder keeps: its chunk as stored, and its scanned planes until a box
/// has carried them. A chain re-sent after a seek or damage scans the stored chunks again,
/// so the keyframes kept back to the last intra one cost their stored size (a detailed
/// 2048² day keeps up to 24, of 2–5 MB each once scanned).
struct KeyData {
    intra: bool,
    chunk: Vec<u8>,
    scanned: Option<(Vec<PlaneSpan>, Vec<SectionSpan>, Coded)>,
}

/// The decoder's state between chunks: parsed keyframes back to the last intra one, and
/// each segment's parts until all have arrived.
pub struct DecoderCore {
    header: Header,
    layout: Layout,
    entries: Vec<IndexEntry>,
    /// Parsed keyframes still needed, by number: keyframe 0 (a loop's end), and the chain
    /// from the last intra keyframe on.
    keys: Vec<Option<KeyData>>,
    tiles: Vec<Option<TileMap>>,
    coeffs: Vec<Option<Vec<u8>>>,
    /// Segments whose tile map or coefficients were damaged: sent with their keyframes
    /// only, once the keyframe after their closing one shows they are complete.
    lost: Vec<bool>,
    /// Keyframe scanning time not yet charged to a segment.
    key_ns: u64,
    /// The device whose staging buffers the boxes go into (`None`: they stay on the CPU,
    /// for benchmarks and tests of the decoder thread alone).
    device: Option<wgpu::Device>,
    /// For a version 2 file whose planes the GPU decodes as coded (`lanes.wgsl`), how
    /// many histograms the file carries; `None`: its planes go as pairs.
    lanes: Option<u32>,
    /// After a seek, the segment it is for: the ones before it get no box (the first box
    /// carries their keyframes in its chain), so that the GPU is not sent them one frame
    /// at a time only to drop them.
    first_segment: usize,
    /// Generation and closing keyframe of the last segment filled: the GPU built that
    /// keyframe last, so the next segment, if it opens with it, need not carry its chain.
    last_closing: Option<(u32, usize)>,
}

impl DecoderCore {
    /// A decoder for the stream described by `header`, `layout` and `entries`.
    pub fn new(header: Header, layout: Layout, entries: Vec<IndexEntry>) -> DecoderCore {
        let k = layout.keyframes.len();
        let s = layout.segments.len();
        let lanes = crate::coded::decodes_lanes(&header);
        DecoderCore {
            lanes,
            header,
            layout,
            entries,
            keys: (0..k).map(|_| None).collect(),
            tiles: vec![None; s],
            coeffs: vec![None; s],
            lost: vec![false; s],
            key_ns: 0,
            device: None,
            first_segment: 0,
            last_closing: None,
        }
    }

    /// Whether a version 2 file's sections go to the GPU as coded (`true`, where the
    /// planes fit the GPU's dense plane; a new core's setting) or decoded to pairs; the
    /// player sets it from its decode shape, whose default is pairs
    /// ([`DecodeShape::lanes`](crate::DecodeShape::lanes)). Before the first chunk.
    pub fn set_lanes(&mut self, on: bool) {
        self.lanes = crate::coded::decodes_lanes(&self.header).filter(|_| on);
    }

    /// Packs each box into a staging buffer of `device` (the pipeline's decoders do; the
    /// render thread then only records a copy).
    pub fn stage_on(&mut self, device: wgpu::Device) {
        self.device = Some(device);
    }

    /// Forgets everything (after a seek).
    #[cfg_attr(not(feature = "bench"), allow(dead_code))]
    pub fn reset(&mut self) {
        self.reset_from(0);
    }

    /// Forgets everything, after a seek to segment `first`: no box is sent for the
    /// segments before it.
    pub fn reset_from(&mut self, first: usize) {
        self.first_segment = first;
        self.keys.iter_mut().for_each(|k| *k = None);
        self.tiles.iter_mut().for_each(|k| *k = None);
        self.coeffs.iter_mut().for_each(|k| *k = None);
        self.lost.iter_mut().for_each(|l| *l = false);
        self.last_closing = None;
    }

    fn damaged(&self, i: usize, what: &str) -> Event {
        let e = self.entries[i];
        Event::Damaged(format!(
            "chunk {i}, frames {}–{}: {what}",
            e.first_frame, e.last_frame
        ))
    }

    /// Takes chunk `i` (its bytes, or `None` if the source failed to deliver it).
    pub fn take(&mut self, i: usize, bytes: Option<&[u8]>) -> Event {
        match self.take_chunk(i, bytes) {
            Event::Ready(s) if s < self.first_segment => Event::Nothing,
            e => e,
        }
    }

    fn take_chunk(&mut self, i: usize, bytes: Option<&[u8]>) -> Event {
        let Some(&e) = self.entries.get(i) else {
            return Event::Nothing;
        };
        let Some(bytes) = bytes else {
            return self.fail(i, "the source failed to deliver it");
        };
        if verify_chunk(i, &e, bytes).is_err() {
            return self.fail(i, "checksum mismatch");
        }
        let n = e.number as usize;
        match e.kind {
            ChunkKind::Keyframe => {
                let t = thread_cpu_ns();
                let mut data = Coded::default();
                let mut planes = Vec::with_capacity(self.header.channels as usize);
                let mut sections = Vec::new();
                let out = (&mut data, &mut planes, &mut sections);
                let mode = push_keyframe(&self.header, self.lanes, bytes, out);
                self.key_ns += thread_cpu_ns() - t;
                let mode = match mode {
                    Ok(m) => m,
                    Err(err) => return self.fail(i, &err.to_string()),
                };
                let intra = mode == chunk::MODE_INTRA;
                // The index says intra: the payload must not need a reference (the CPU
                // decoder refuses such a keyframe too).
                if e.is_intra() && !intra {
                    return self.fail(i, "predicted keyframe without its reference");
                }
                if !intra && (n == 0 || self.keys[n - 1].is_none()) {
                    // The chain is broken (damage, or we started mid-stream): wait for an
                    // intra keyframe.
                    self.keys[n] = None;
                    return Event::Nothing;
                }
                self.keys[n] = Some(KeyData {
                    intra,
                    chunk: bytes.to_vec(),
                    scanned: Some((planes, sections, data)),
                });
                // Segments before n − 1 are complete or lost by now (their chunks come
                // first). Segment n − 1 may need its chain from the last intra keyframe
                // before it: keep that one on (and keyframe 0, for a loop's end).
                let last_intra = (0..n)
                    .rev()
                    .find(|&k| self.keys[k].as_ref().is_some_and(|key| key.intra))
                    .unwrap_or(0);
                for k in 1..last_intra {
                    self.keys[k] = None;
                }
                for s in 0..n.saturating_sub(1) {
                    self.tiles[s] = None;
                    self.coeffs[s] = None;
                }
                // Segment n − 2 lost its tile map or coefficients: its chunks are all
                // past, so send its keyframes alone now.
                if n >= 2 && self.lost[n - 2] && self.keys[n - 2].is_some() {
                    return Event::Ready(n - 2);
                }
                // A keyframe can complete the segment it closes (the last of a looping
                // file is closed by keyframe 0, which arrives first).
                if n > 0 && self.complete(n - 1) {
                    return Event::Ready(n - 1);
                }
                Event::Nothing
            }
            ChunkKind::TileMap => {
                let len = e.last_frame - e.first_frame;
                match chunk::read_tilemap(&self.header, bytes, len) {
                    Ok(t) => {
                        self.tiles[n] = Some(t);
                        Event::Nothing
                    }
                    Err(err) => self.fail(i, &err.to_string()),
                }
            }
            ChunkKind::Coefficients => {
                self.coeffs[n] = Some(bytes.to_vec());
                if self.complete(n) {
                    Event::Ready(n)
                } else {
                    Event::Nothing
                }
            }
            _ => Event::Nothing,
        }
    }

    /// The intra keyframe that starts the chain to keyframe `k`, if the decoder holds
    /// every keyframe of it.
    fn chain_start(&self, k: usize) -> Option<usize> {
        let mut j = k;
        loop {
            let key = self.keys.get(j)?.as_ref()?;
            if key.intra {
                return Some(j);
            }
            j = j.checked_sub(1)?;
        }
    }

    fn fail(&mut self, i: usize, what: &str) -> Event {
        let e = self.entries[i];
        let n = e.number as usize;
        match e.kind {
            ChunkKind::Keyframe => self.keys[n] = None,
            ChunkKind::TileMap | ChunkKind::Coefficients => {
                self.tiles[n] = None;
                self.coeffs[n] = None;
                self.lost[n] = true;
            }
            _ => {}
        }
        self.damaged(i, what)
    }

    fn complete(&self, s: usize) -> bool {
        let k1 = self.layout.keyframe_of_boundary(s + 1);
        self.keys[s].is_some()
            && self.keys[k1].is_some()
            && self.tiles[s].is_some()
            && self.coeffs[s].is_some()
    }

    /// Packs segment `s` into `out`. Its coefficient bytes are consumed.
    pub fn fill(
        &mut self,
        s: usize,
        generation: u32,
        pass: u32,
        out: &mut SegmentData,
    ) -> Result<(), String> {
        let t0 = thread_cpu_ns();
        let h = &self.header;
        let ch = h.channels as usize;
        let k1n = self.layout.keyframe_of_boundary(s + 1);
        out.steps.clear();
        out.planes.clear();
        out.sections.clear();
        out.data.clear();
        out.staged = None;
        // The keyframes: K_{s+1} alone when the GPU built K_s last, else the chain.
        let first = if self.last_closing == Some((generation, s)) {
            None
        } else {
            Some(
                self.chain_start(s)
                    .ok_or_else(|| format!("keyframe {s}: its chain is not decoded"))?,
            )
        };
        // Whatever happens below, the GPU will not have built what this box closes on.
        self.last_closing = None;
        let chain = first.map_or(0..0, |f| f..s + 1);
        for k in chain.chain(std::iter::once(k1n)) {
            let key = self.keys[k]
                .as_mut()
                .ok_or_else(|| format!("keyframe {k} missing"))?;
            out.steps.push(KeyStep {
                number: k,
                intra: key.intra,
                plane: out.planes.len(),
            });
            // Scanned when it arrived, unless a box has carried it since: then again.
            match key.scanned.take() {
                Some((planes, sections, data)) => out.data.push_copy(
                    &data,
                    (&planes, &sections),
                    (&mut out.planes, &mut out.sections),
                ),
                None => {
                    let to = (&mut out.data, &mut out.planes, &mut out.sections);
                    push_keyframe(&self.header, self.lanes, &key.chunk, to)
                        .map_err(|e| format!("keyframe {k}: {e}"))?;
                }
            }
        }
        out.keys_only = std::mem::take(&mut self.lost[s]);
        out.bubbles = out.planes.len();
        if out.keys_only {
            self.finish_box(s, generation, pass, 2, k1n, t0, out);
            return Ok(());
        }
        let tiles = self.tiles[s].take().ok_or("tile map missing")?;
        let bytes = self.coeffs[s].take().ok_or("coefficients missing")?;
        let context = |e: vbim_format::FormatError| {
            let (_, ci) = self.layout.segments[s];
            let en = self.entries[ci];
            format!(
                "chunk {ci}, frames {}–{}: {e}",
                en.first_frame, en.last_frame
            )
        };
        if let Some(lanes) = self.lanes {
            // Version 2, decoded by the GPU as coded: the section as it is.
            let to = (&mut out.data, &mut out.planes, &mut out.sections);
            let what = Payload::Coefficients(&tiles);
            push_lanes(h, lanes, what, &bytes, to).map_err(context)?;
            let layers = 1 + tiles.max_degree() as usize;
            self.finish_box(s, generation, pass, layers, k1n, t0, out);
            return Ok(());
        }
        let mut bubbles = chunk::CoeffReader::open(h, &bytes, &tiles).map_err(context)?;
        let layers = 1 + bubbles.max_degree() as usize;
        let n = h.tile_count();
        for k in 2..layers {
            for p in 0..ch {
                // The plane's blocks are those of the tiles of degree ≥ k, tile by tile.
                let degrees = tiles.degrees(p);
                let member = |t: usize| degrees[t] >= k as u8;
                let data = &mut out.data;
                let planes = &mut out.planes;
                bubbles
                    .scan_plane(k as u8, p, |step, s| {
                        planes.push(data.push_plane(step, s, Some((n, &member))));
                    })
                    .map_err(context)?;
            }
        }
        bubbles.finish().map_err(context)?;
        self.finish_box(s, generation, pass, layers, k1n, t0, out);
        Ok(())
    }

    /// Fills in a packed box's description and forgets what the GPU now has.
    #[allow(clippy::too_many_arguments)]
    fn finish_box(
        &mut self,
        s: usize,
        generation: u32,
        pass: u32,
        layers: usize,
        k1n: usize,
        t0: u64,
        out: &mut SegmentData,
    ) {
        // Past the seek's segment: later passes play from segment 0 again.
        self.first_segment = 0;
        out.generation = generation;
        out.pass = pass;
        out.index = s;
        out.start = self.layout.boundaries[s];
        out.end = self.layout.boundaries[s + 1];
        out.layers = layers;
        out.keys = [s, k1n];
        self.last_closing = Some((generation, k1n));
        if let Some(device) = self.device.as_ref().filter(|_| out.data.bytes() > 0) {
            out.stage(device);
        }
        out.decode_ns = thread_cpu_ns() - t0 + std::mem::take(&mut self.key_ns);
        // The GPU holds the chain up to K_{s+1} now: only keyframe 0 (a loop's end) and
        // the ones ahead are needed here.
        for k in 1..=s {
            if k != k1n {
                self.keys[k] = None;
            }
        }
    }
}

/// Quantiser step `i` of a payload's head (after its four bytes of mode or degree and
/// planes), which the caller checked holds it.
fn step_of(payload: &[u8], i: usize) -> f32 {
    let at = 4 + 4 * i;
    f32::from_le_bytes([
        payload[at],
        payload[at + 1],
        payload[at + 2],
        payload[at + 3],
    ])
}

/// Appends keyframe chunk `bytes`'s planes: for a version 2 file the GPU decodes as coded
/// (`lanes`: the file's histogram count), its section as it is; otherwise each plane's
/// pairs and entry points (decompressed, or a version 2 section decoded to pairs, and
/// scanned). Returns its mode byte.
fn push_keyframe(
    h: &Header,
    lanes: Option<u32>,
    bytes: &[u8],
    (data, planes, sections): Boxed<'_>,
) -> vbim_format::Result<u8> {
    match lanes {
        Some(lanes) => push_lanes(h, lanes, Payload::Keyframe, bytes, (data, planes, sections))
            .map(|()| bytes[0]),
        None => chunk::keyframe_streams(h, bytes, |_, step, s| {
            planes.push(data.push_plane(step, s, None));
        }),
    }
}

/// Where a chunk's planes go in a box: its words, its planes, its sections.
type Boxed<'a> = (
    &'a mut Coded,
    &'a mut Vec<PlaneSpan>,
    &'a mut Vec<SectionSpan>,
);

/// Appends a version 2 keyframe or coefficient chunk's section as it is, and each of its
/// planes (a bubble plane with its member tiles), for the GPU to decode as coded;
/// `file_count` is how many histograms the file carries.
fn push_lanes(
    h: &Header,
    file_count: u32,
    what: Payload,
    bytes: &[u8],
    (data, planes, sections): Boxed<'_>,
) -> vbim_format::Result<()> {
    let maps = h.context_maps().ok_or_else(|| {
        vbim_format::FormatError::Invalid("a version 1 file has no coefficient sections".into())
    })?;
    let (head, shapes) = section_planes(h, what, bytes)?;
    let layout = h
        .lane_layout()
        .unwrap_or(vbim_format::plane2::Layout::OneState);
    let section = Section::parse_layout(&bytes[head..], &shapes, maps, layout)?;
    let index = sections.len() as u32;
    sections.push(data.push_section(&bytes[head..], &section, file_count));
    let (w, ht) = chunk::padded_size(h);
    let (ch, n, per) = (
        h.channels as usize,
        h.tile_count(),
        h.tile_size as usize / 8,
    );
    for (i, (sp, shape)) in section.planes.iter().zip(&shapes).enumerate() {
        let plane = (sp, index, shape.family);
        let span = match what {
            Payload::Keyframe => {
                data.push_lane_plane(step_of(bytes, i), plane, (w / 8) * (ht / 8), None)
            }
            // Term k = i / channels + 2 of plane i % channels: the tiles whose degree
            // reaches k.
            Payload::Coefficients(tiles) => {
                let (k, p) = ((i / ch + 2) as u8, i % ch);
                let degrees = tiles.degrees(p);
                let member = |t: usize| degrees[t] >= k;
                let blocks = degrees.iter().filter(|&&d| d >= k).count() * per * per;
                let members = Some((n, &member as &dyn Fn(usize) -> bool));
                data.push_lane_plane(step_of(bytes, i), plane, blocks, members)
            }
        };
        planes.push(span);
    }
    Ok(())
}
