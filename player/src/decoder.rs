//! The decoder: takes chunks from the ring, verifies them, keeps the keyframe chain, and
//! when a segment's keyframes, tile map and coefficients are all there decodes it into a
//! staging buffer laid out for upload (one f32 layer per plane of each term).
//!
//! A damaged chunk (checksum mismatch, or the source failed) is reported and makes what
//! depends on it undecodable: a keyframe breaks the predicted chain until the next intra
//! keyframe, a tile map or coefficient chunk only its segment. Playback resumes with the
//! first segment whose parts are all good.

use crate::cpu_time::thread_cpu_ns;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use vbim_format::chunk::{self, TileMap};
use vbim_format::index::Layout;
use vbim_format::plane::Plane;
use vbim_format::reader::verify_chunk;
use vbim_format::{ChunkKind, Header, IndexEntry};

/// Where the decoder writes a segment's layers.
#[cfg_attr(not(feature = "bench"), allow(dead_code))]
pub enum Staging {
    /// Host memory (the decoder measured on its own, `vbim bench decode`).
    Host(Vec<f32>),
    /// A GPU staging buffer (`MAP_WRITE | COPY_SRC`), mapped while the decoder thread
    /// writes into it: the render thread then only unmaps it and records one copy into
    /// the texture slot — the bytes are never touched on the render thread.
    Mapped(wgpu::Buffer),
}

/// A decoded segment, ready to upload: for each term (0 = K_s, 1 = K_{s+1}, 2.. = bubble
/// coefficients) one f32 layer per plane of the coded domain (Y, Co, Cg, or Y alone), of
/// width × height texels, rows `row_pitch` bytes apart (a multiple of 256, as
/// buffer-to-texture copies require). Planar, so that the decoder copies plane rows as
/// they are instead of interleaving texels, and no padding channel is uploaded.
///
/// Term 0 is left unwritten (`k0_staged == false`) when the segment the decoder sent just
/// before was the one this segment follows: its closing keyframe is this segment's opening
/// one, and the render thread has it on the GPU already (it uploads every segment's
/// closing keyframe, even one it drops). That saves a term's copy per segment, on the
/// decoder and on the GPU.
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
    /// Terms (each `channels` layers).
    pub layers: usize,
    /// Keyframe numbers of K_s and K_{s+1}.
    pub keys: [usize; 2],
    /// Whether term 0 (K_s) is in staging; if not, the GPU has it from the segment before.
    pub k0_staged: bool,
    /// Where its layers are written.
    pub staging: Staging,
    /// Set once a `Mapped` staging buffer is mapped again after its upload (by wgpu's
    /// callback): only then may it go back to the decoder.
    pub mapped: Arc<AtomicBool>,
    /// CPU nanoseconds (the decoding thread's own clock) spent on this segment and its
    /// closing keyframe.
    pub decode_ns: u64,
    /// For each bubble layer's tiles (`[(term · channels + plane) · tiles + tile]`):
    /// whether staging holds zeros there. A staging buffer keeps its contents from one
    /// segment to the next (it is mapped again, not replaced), and a tile whose degree
    /// is below a term is zero in that term's layer: such a tile is written only when the
    /// box's last segment left something else there. On the cloudy benchmark days 44–52%
    /// of the bubble layers' tiles are zero.
    zero_tiles: Vec<bool>,
}

/// Bytes between rows of a staging layer (one plane of one term).
pub fn row_pitch(width: u32) -> u64 {
    (width as u64 * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64)
}

/// Bytes of one staging layer (one plane of one term).
pub fn layer_bytes(h: &Header) -> u64 {
    row_pitch(h.width) * h.height as u64
}

/// Bytes of one term: all its planes.
pub fn term_bytes(h: &Header) -> u64 {
    h.channels as u64 * layer_bytes(h)
}

impl SegmentData {
    fn empty(staging: Staging) -> SegmentData {
        SegmentData {
            generation: 0,
            pass: 0,
            index: 0,
            start: 0,
            end: 0,
            layers: 0,
            keys: [0, 0],
            k0_staged: true,
            staging,
            mapped: Arc::new(AtomicBool::new(true)),
            decode_ns: 0,
            // Both kinds of staging start zeroed (a new buffer is zero-initialised).
            zero_tiles: Vec::new(),
        }
    }

    /// A host-memory staging box (for measuring the decoder without a GPU).
    #[cfg_attr(not(feature = "bench"), allow(dead_code))]
    pub fn with_capacity(h: &Header) -> SegmentData {
        let layers = h.max_degree as usize + 1;
        let floats = layers as u64 * term_bytes(h) / 4;
        SegmentData::empty(Staging::Host(Vec::with_capacity(floats as usize)))
    }

    /// A staging box backed by a mapped GPU buffer large enough for any segment of `h`.
    pub fn mapped(h: &Header, device: &wgpu::Device) -> SegmentData {
        let layers = h.max_degree as u64 + 1;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim staging"),
            size: layers * term_bytes(h),
            usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        });
        SegmentData::empty(Staging::Mapped(buffer))
    }

    /// Bytes of the segment's layers written into staging (at most what its upload
    /// copies).
    #[cfg_attr(not(feature = "bench"), allow(dead_code))]
    pub fn bytes(&self, h: &Header) -> u64 {
        (self.layers as u64 - !self.k0_staged as u64) * term_bytes(h)
    }
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

/// A keyframe the decoder has.
#[derive(Clone)]
enum Key {
    Planes(Arc<Vec<Plane>>),
    /// Its planes became the next predicted keyframe's. Only done when the segment it
    /// opens will not stage it: the segment before, which it closes, was filled, and the
    /// render thread has it on the GPU.
    OnGpu,
}

/// The decoder's state between chunks: the keyframe chain, and each segment's parts
/// until all have arrived.
pub struct DecoderCore {
    header: Header,
    layout: Layout,
    entries: Vec<IndexEntry>,
    /// Keyframes still needed: by keyframe number.
    keys: Vec<Option<Key>>,
    tiles: Vec<Option<TileMap>>,
    coeffs: Vec<Option<Vec<u8>>>,
    /// The last keyframe decoded, for the predicted chain.
    chain: Option<(usize, Arc<Vec<Plane>>)>,
    /// Keyframe decoding time not yet charged to a segment.
    key_ns: u64,
    /// Scratch band for decoding bubble planes row band by row band.
    band: Plane,
    /// Generation and closing keyframe of the last segment filled: the next segment,
    /// if it opens with that keyframe, need not stage it again.
    last_closing: Option<(u32, usize)>,
}

impl DecoderCore {
    /// A decoder for the stream described by `header`, `layout` and `entries`.
    pub fn new(header: Header, layout: Layout, entries: Vec<IndexEntry>) -> DecoderCore {
        let k = layout.keyframes.len();
        let s = layout.segments.len();
        DecoderCore {
            header,
            layout,
            entries,
            keys: vec![None; k],
            tiles: vec![None; s],
            coeffs: vec![None; s],
            chain: None,
            key_ns: 0,
            band: Plane::zeros(0, 0),
            last_closing: None,
        }
    }

    /// Forgets everything (after a seek).
    pub fn reset(&mut self) {
        self.keys.iter_mut().for_each(|k| *k = None);
        self.tiles.iter_mut().for_each(|k| *k = None);
        self.coeffs.iter_mut().for_each(|k| *k = None);
        self.chain = None;
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
                // The reference: K_{n−1}, if the chain holds it. When the segment K_{n−1}
                // opens will not stage it (the segment before, closed by it, was filled),
                // no one needs its planes on the CPU any more — except keyframe 0, kept
                // for a loop's end — and K_n is built in them instead of a copy.
                let (mut owned, mut held) = (None, None);
                match self.chain.take() {
                    Some((k, p)) if k + 1 == n => {
                        if k > 0 && self.last_closing.is_some_and(|(_, c)| c == k) {
                            self.keys[k] = Some(Key::OnGpu);
                        }
                        // Unique unless `keys[k]` still holds it.
                        match Arc::try_unwrap(p) {
                            Ok(planes) => owned = Some(planes),
                            Err(p) => held = Some(p),
                        }
                    }
                    other => self.chain = other,
                }
                let prev = match (owned, &held) {
                    // The index says intra: no reference, whatever the payload says (the
                    // CPU decoder starts such a keyframe without one too, so a payload
                    // that disagrees is refused by both).
                    _ if e.is_intra() => chunk::Reference::None,
                    (Some(planes), _) => chunk::Reference::Owned(planes),
                    (None, Some(p)) => chunk::Reference::Borrowed(&p[..]),
                    (None, None) if !e.is_intra() => {
                        // The chain is broken (damage, or we started mid-stream): wait for
                        // an intra keyframe.
                        self.keys[n] = None;
                        return Event::Nothing;
                    }
                    (None, None) => chunk::Reference::None,
                };
                let t = thread_cpu_ns();
                match chunk::read_keyframe_from(&self.header, bytes, prev) {
                    Ok(planes) => {
                        self.key_ns += thread_cpu_ns() - t;
                        let planes = Arc::new(planes);
                        self.keys[n] = Some(Key::Planes(planes.clone()));
                        self.chain = Some((n, planes));
                        // Drop keyframes no segment ahead needs (keyframe 0 stays for a loop).
                        for k in 1..n.saturating_sub(1) {
                            self.keys[k] = None;
                        }
                        self.ready_after_key(n)
                    }
                    Err(err) => self.fail(i, &err.to_string()),
                }
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

    fn ready_after_key(&self, k: usize) -> Event {
        // A keyframe can complete the segment it closes (the last of a looping file is
        // closed by keyframe 0, which arrives first).
        if k > 0 && self.complete(k - 1) {
            return Event::Ready(k - 1);
        }
        Event::Nothing
    }

    fn fail(&mut self, i: usize, what: &str) -> Event {
        let e = self.entries[i];
        let n = e.number as usize;
        match e.kind {
            ChunkKind::Keyframe => {
                self.keys[n] = None;
                if self.chain.as_ref().is_some_and(|(k, _)| *k + 1 == n) {
                    self.chain = None;
                }
            }
            ChunkKind::TileMap => self.tiles[n] = None,
            ChunkKind::Coefficients => self.coeffs[n] = None,
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

    /// Decodes segment `s` into `out`. Its coefficient bytes are consumed.
    pub fn fill(
        &mut self,
        s: usize,
        generation: u32,
        pass: u32,
        out: &mut SegmentData,
    ) -> Result<(), String> {
        let t0 = thread_cpu_ns();
        // wgpu panics on writing a buffer that is not mapped: a box only comes back to
        // the decoder once its buffer is mapped again, so this is a broken contract.
        if matches!(out.staging, Staging::Mapped(_)) && !out.mapped.load(Ordering::Acquire) {
            return Err("staging buffer not mapped".into());
        }
        let h = &self.header;
        let k1n = self.layout.keyframe_of_boundary(s + 1);
        let k0_staged = self.last_closing != Some((generation, s));
        let planes = |k: usize| match &self.keys[k] {
            Some(Key::Planes(p)) => Ok(p.clone()),
            Some(Key::OnGpu) => Err(format!("keyframe {k} is no longer decoded")),
            None => Err(format!("keyframe {k} missing")),
        };
        let k1 = planes(k1n)?;
        // K_s only when it is staged.
        let k0 = if k0_staged { Some(planes(s)?) } else { None };
        // Whatever happens below, the box's old contents are not what it is about to hold.
        self.last_closing = None;
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
        let mut bubbles = chunk::CoeffReader::open(h, &bytes, &tiles).map_err(context)?;
        let (w, ht) = (h.width as usize, h.height as usize);
        let ch = h.channels as usize;
        let layers = 1 + bubbles.max_degree() as usize;
        let stride = row_pitch(h.width) as usize / 4;
        let layer = layer_bytes(h) as usize;
        let tile_count = h.tile_count();
        let flags = (h.max_degree as usize + 1) * ch * tile_count;
        if out.zero_tiles.len() != flags {
            out.zero_tiles = vec![true; flags];
        }
        // Term `l`, plane `p` is staging layer l·channels + p: each row is written as it is
        // (the padding columns and rows of the coded planes are left out).
        for (l, key) in [(0, k0.as_ref()), (1, Some(&k1))] {
            let Some(key) = key else {
                continue;
            };
            for (p, plane) in key.iter().enumerate().take(ch) {
                with_layer(&mut out.staging, (l * ch + p) * layer, layer, |o| {
                    for y in 0..ht {
                        o.copy(y * stride, &plane.data[y * plane.w..y * plane.w + w]);
                    }
                    Ok(())
                })?;
            }
        }
        let band = &mut self.band;
        for l in 2..layers {
            for p in 0..ch {
                let li = l * ch + p;
                let zero = &mut out.zero_tiles[li * tile_count..(li + 1) * tile_count];
                with_layer(&mut out.staging, li * layer, layer, |o| {
                    bubbles
                        .read_plane(l as u8, p, band, |r| {
                            write_tile_row(o, (w, ht, stride), &r, zero)
                        })
                        .map_err(context)
                })?;
            }
        }
        bubbles.finish().map_err(context)?;
        // The box goes to the render thread next.
        fence_streaming();
        out.generation = generation;
        out.pass = pass;
        out.index = s;
        out.start = self.layout.boundaries[s];
        out.end = self.layout.boundaries[s + 1];
        out.layers = layers;
        out.keys = [s, k1n];
        out.k0_staged = k0_staged;
        self.last_closing = Some((generation, k1n));
        out.decode_ns = thread_cpu_ns() - t0 + std::mem::take(&mut self.key_ns);
        // Keyframe s is no longer needed unless it is keyframe 0 (a loop's end).
        if s > 0 {
            self.keys[s] = None;
        }
        Ok(())
    }
}

/// One staging layer open for writing, addressed in texels. Write-only: a mapped
/// buffer may be write-combined memory, where reading back is slow.
enum LayerOut<'a> {
    Host(&'a mut [f32]),
    Mapped(wgpu::BufferViewMut),
}

impl LayerOut<'_> {
    fn copy(&mut self, at: usize, src: &[f32]) {
        match self {
            // SAFETY: both ranges are `src.len()` f32 values, bounds-checked by `slice`.
            LayerOut::Host(t) => unsafe { copy_streaming(t[at..at + src.len()].as_mut_ptr(), src) },
            LayerOut::Mapped(v) => unsafe {
                let mut range = v.slice(at * 4..(at + src.len()) * 4);
                copy_streaming(range.as_raw_ptr().cast::<f32>().as_ptr(), src)
            },
        }
    }

    fn zero(&mut self, at: usize, len: usize) {
        match self {
            LayerOut::Host(t) => t[at..at + len].fill(0.0),
            // All-zero bytes are 0.0f32.
            LayerOut::Mapped(v) => v.slice(at * 4..(at + len) * 4).fill(0),
        }
    }
}

/// Copies `src` to `dst` with non-temporal stores: the decoder never reads staging back,
/// so its lines need not displace the band, the keyframes and the coefficient stream from
/// the cache, nor be read from memory before being overwritten.
///
/// # Safety
/// `dst` must be valid for writing `src.len()` f32 values (any alignment).
unsafe fn copy_streaming(dst: *mut f32, src: &[f32]) {
    let n = src.len();
    #[cfg(target_arch = "x86_64")]
    // SAFETY: every write is inside dst[0..n] (the caller's promise); the streamed ones are
    // 16-byte aligned (`head` aligns them, steps are 16 bytes); SSE is part of x86-64.
    unsafe {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_stream_ps};
        let head = dst.align_offset(16).min(n);
        let body = head + (n - head) / 4 * 4;
        for i in (0..head).chain(body..n) {
            dst.add(i).write_unaligned(src[i]);
        }
        for i in (head..body).step_by(4) {
            _mm_stream_ps(dst.add(i), _mm_loadu_ps(src.as_ptr().add(i)));
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    // SAFETY: as the caller promises; bytes have no alignment.
    unsafe {
        std::ptr::copy_nonoverlapping(src.as_ptr().cast::<u8>(), dst.cast::<u8>(), n * 4)
    };
}

/// Non-temporal stores are weakly ordered: this makes the ones before it visible before
/// any store after it (such as handing the staging box to another thread).
fn fence_streaming() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of x86-64.
    unsafe {
        std::arch::x86_64::_mm_sfence()
    };
}

/// Runs `write` on the staging layer at byte `base` (`len` bytes).
fn with_layer(
    staging: &mut Staging,
    base: usize,
    len: usize,
    write: impl FnOnce(&mut LayerOut) -> Result<(), String>,
) -> Result<(), String> {
    match staging {
        Staging::Host(v) => {
            if v.len() < (base + len) / 4 {
                v.resize((base + len) / 4, 0.0);
            }
            write(&mut LayerOut::Host(&mut v[base / 4..(base + len) / 4]))
        }
        Staging::Mapped(b) => {
            // Mapped: `fill` refuses a box whose `mapped` flag is not set.
            let view = b.get_mapped_range_mut(base as u64..(base + len) as u64);
            write(&mut LayerOut::Mapped(view))
        }
    }
}

/// Writes one row of tiles of a bubble layer into staging (`w` × `ht` texels, rows
/// `stride` texels apart, the coded plane's padding left out): member tiles from the band,
/// zeros where the layer's last contents were not zero, nothing where they were.
fn write_tile_row(
    out: &mut LayerOut,
    (w, ht, stride): (usize, usize, usize),
    r: &chunk::TileRows<'_>,
    zero: &mut [bool],
) {
    let ts = r.tile_size;
    let rows = r.y0..(r.y0 + ts).min(ht);
    let first_tile = (r.y0 / ts) * r.degrees.len();
    let zero = &mut zero[first_tile..first_tile + r.degrees.len()];
    for (y, x0, values) in r.member_rows() {
        if y < ht && x0 < w {
            out.copy(y * stride + x0, &values[..values.len().min(w - x0)]);
        }
    }
    for (a, b) in chunk::spans(zero.len(), |t| !r.is_member(t) && !zero[t]) {
        let (a, b) = ((a * ts).min(w), (b * ts).min(w));
        for y in rows.clone() {
            out.zero(y * stride + a, b - a);
        }
    }
    for (t, z) in zero.iter_mut().enumerate() {
        *z = !r.is_member(t);
    }
}

#[cfg(test)]
mod tests {
    use super::{copy_streaming, fence_streaming};

    #[test]
    fn streaming_copy_writes_exactly_its_range_at_any_alignment() {
        let src: Vec<f32> = (0..67).map(|i| i as f32 * 1.5 - 20.0).collect();
        for offset in 0..5 {
            for len in [0, 1, 3, 4, 5, 8, 13, 16, 31, 60] {
                // Destination bytes start at `offset` bytes past a 16-byte boundary (so
                // also at addresses f32 would not be aligned to), between guard values.
                let mut bytes = vec![0xA5u8; 16 * 20];
                let base = bytes.as_ptr().align_offset(16) + offset;
                // SAFETY: base + 4·len lies inside `bytes` (16·20 bytes).
                unsafe {
                    copy_streaming(bytes.as_mut_ptr().add(base).cast::<f32>(), &src[..len]);
                }
                fence_streaming();
                let got: Vec<f32> = bytes[base..base + 4 * len]
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                    .collect();
                assert_eq!(got, &src[..len], "offset {offset}, length {len}");
                assert!(bytes[..base].iter().all(|&b| b == 0xA5));
                assert!(bytes[base + 4 * len..].iter().all(|&b| b == 0xA5));
            }
        }
    }
}
