//! The reader: pulls chunks from the source in playback order — wrapping to the start of a
//! looping file before the loop point — and frames them into the ring of compressed bytes.
//! Arrival times follow the [`Throttle`] on the playback clock.

use std::io::{Read, Seek, SeekFrom};

use ringbuf::traits::{Consumer, Observer, Producer};
use ringbuf::{HeapCons, HeapProd};
use vbim_format::{ChunkKind, IndexEntry};

use crate::throttle::Throttle;

/// Bytes of a message header in the ring: generation, pass, chunk index, length.
pub const MSG_HEADER: usize = 16;
/// Length value of a chunk the source failed to deliver.
pub const FAILED: u32 = u32::MAX;

/// A chunk read but not yet in the ring.
pub struct Pending {
    pub chunk: u32,
    pub pass: u32,
    pub bytes: Vec<u8>,
    pub failed: bool,
    pub arrival: u64,
}

pub struct ReaderCore<R> {
    src: R,
    entries: Vec<IndexEntry>,
    looping: bool,
    pos: usize,
    /// Times the reader has wrapped to the start of a looping file.
    pub pass: u32,
    pub generation: u32,
    pub throttle: Throttle,
    /// When the previous chunk finished arriving.
    last_arrival: u64,
    pub pending: Option<Pending>,
    pub bytes_read: u64,
    pub finished: bool,
    first: Option<usize>,
    ring_blocked: bool,
    buf: Vec<u8>,
}

impl<R: Read + Seek> ReaderCore<R> {
    pub fn new(src: R, entries: Vec<IndexEntry>, looping: bool, throttle: Throttle) -> Self {
        let max = entries.iter().map(|e| e.length).max().unwrap_or(0) as usize;
        ReaderCore {
            src,
            entries,
            looping,
            pos: 0,
            pass: 0,
            generation: 0,
            throttle,
            last_arrival: 0,
            pending: None,
            bytes_read: 0,
            finished: false,
            first: None,
            ring_blocked: false,
            buf: Vec::with_capacity(max),
        }
    }

    /// Restarts reading at chunk `pos` (a seek), from time `now`.
    /// `first`, if given, is read before `pos` (keyframe 0, which closes a looping file's
    /// last segment).
    pub fn restart(&mut self, pos: usize, pass: u32, first: Option<usize>, now: u64) {
        self.pos = pos;
        self.pass = pass;
        self.first = first;
        self.generation = self.generation.wrapping_add(1);
        self.pending = None;
        self.finished = false;
        self.last_arrival = now;
    }

    /// Chunks in the file.
    pub fn chunk_count(&self) -> usize {
        self.entries.len()
    }

    /// Reads the next chunk from the source (if none is pending) and schedules its arrival.
    pub fn prepare(&mut self) {
        if self.pending.is_some() || self.finished {
            return;
        }
        let i = if let Some(f) = self.first.take() {
            f
        } else {
            if self.pos >= self.entries.len() {
                if !self.looping {
                    self.finished = true;
                    return;
                }
                self.pos = 0;
                self.pass += 1;
            }
            self.pos += 1;
            self.pos - 1
        };
        let e = self.entries[i];
        if e.kind == ChunkKind::Metadata && (self.pass > 0 || self.generation > 0)
            || e.is_optional() && e.kind != ChunkKind::Metadata
        {
            // Skipped: metadata after the first pass, unknown optional chunks.
            return self.prepare();
        }
        self.buf.clear();
        self.buf.resize(e.length as usize, 0);
        let ok = self.src.seek(SeekFrom::Start(e.offset)).is_ok()
            && self.src.read_exact(&mut self.buf).is_ok();
        let arrival = self.throttle.arrival(self.last_arrival, e.length);
        self.last_arrival = arrival;
        self.pending = Some(Pending {
            chunk: i as u32,
            pass: self.pass,
            bytes: std::mem::take(&mut self.buf),
            failed: !ok,
            arrival,
        });
    }

    /// Pushes the pending chunk into the ring if it has arrived by `now` and fits. Returns
    /// whether it did.
    pub fn deliver(&mut self, now: u64, ring: &mut HeapProd<u8>) -> bool {
        let Some(p) = &self.pending else { return false };
        if p.arrival > now {
            return false;
        }
        if ring.vacant_len() < MSG_HEADER + p.bytes.len() {
            // The ring is full: the source is not read meanwhile, so the next chunk's
            // transfer starts when this one gets in.
            self.ring_blocked = true;
            return false;
        }
        let p = self.pending.take().unwrap();
        if std::mem::take(&mut self.ring_blocked) {
            self.last_arrival = now;
        }
        let len = if p.failed {
            FAILED
        } else {
            p.bytes.len() as u32
        };
        let mut head = [0u8; MSG_HEADER];
        head[..4].copy_from_slice(&self.generation.to_le_bytes());
        head[4..8].copy_from_slice(&p.pass.to_le_bytes());
        head[8..12].copy_from_slice(&p.chunk.to_le_bytes());
        head[12..].copy_from_slice(&len.to_le_bytes());
        // The consumer takes a message only once all of it is in the ring.
        ring.push_slice(&head);
        if !p.failed {
            ring.push_slice(&p.bytes);
        }
        self.bytes_read += p.bytes.len() as u64;
        // Keep the buffer for the next chunk: no allocation per chunk in steady state.
        self.buf = p.bytes;
        true
    }

    /// The arrival time of the pending chunk, if any.
    pub fn next_arrival(&self) -> Option<u64> {
        self.pending.as_ref().map(|p| p.arrival)
    }
}

/// A message taken from the ring.
pub struct Message {
    pub generation: u32,
    pub pass: u32,
    pub chunk: u32,
    /// False: the source failed to deliver this chunk.
    pub ok: bool,
}

/// Pops one whole message into `buf` if all of it is in the ring.
pub fn pop_message(ring: &mut HeapCons<u8>, buf: &mut Vec<u8>) -> Option<Message> {
    if ring.occupied_len() < MSG_HEADER {
        return None;
    }
    let mut head = [0u8; MSG_HEADER];
    ring.peek_slice(&mut head);
    let generation = u32::from_le_bytes(head[..4].try_into().unwrap());
    let pass = u32::from_le_bytes(head[4..8].try_into().unwrap());
    let chunk = u32::from_le_bytes(head[8..12].try_into().unwrap());
    let len = u32::from_le_bytes(head[12..].try_into().unwrap());
    let body = if len == FAILED { 0 } else { len as usize };
    if ring.occupied_len() < MSG_HEADER + body {
        return None;
    }
    ring.skip(MSG_HEADER);
    buf.clear();
    buf.resize(body, 0);
    ring.pop_slice(buf);
    Some(Message {
        generation,
        pass,
        chunk,
        ok: len != FAILED,
    })
}
