//! Entry points into a coefficient stream, for a parser that starts mid-stream: the GPU
//! player parses each plane's stream in many pieces at once, one invocation per entry
//! point.
//!
//! A stream ([`crate::plane::write_coefficients`]) is a sequence of (zero run, value)
//! pairs over the positions `f · n + b` (frequency f of block b, n blocks); the first n
//! positions hold each block's DC as the difference from the previous block's. Parsing a
//! pair needs the byte where it starts, the position its run counts from and, in the DC
//! range, the running DC. [`scan`] walks the stream once and notes these three numbers
//! every [`ENTRY_PAIRS`] pairs. It stores no coefficient, so it costs about half of what
//! zstd does, and it refuses everything [`crate::plane::read_blocks`] refuses (a run past
//! the end, a truncated or over-long varint): a parser that starts from its entry points
//! only ever sees well-formed pairs.
//!
//! In the DC range a zero run means "the same DC again" for every block it passes, and a
//! parser writes that DC into each of them. On a smooth plane one run can pass the whole
//! plane: a million blocks at 8192², which one GPU invocation took half a second to write
//! (BENCHMARKS.md, "On a hardware GPU"). So the scan also starts a piece inside such a run every
//! [`FILL_BLOCKS`] blocks: a piece starts filling at its entry's `from` and stops where
//! the next piece starts filling, and no piece fills more than [`FILL_BLOCKS`] blocks.

use crate::dct::N;
use crate::{varint, FormatError, Result};

/// Pairs between two entry points: a piece one invocation parses in sequence. On a GPU a
/// plane's parse takes as long as its longest piece (a 512² plane has a few dozen pieces
/// of 256 pairs, where a GPU runs thousands of invocations at once), so shorter is
/// faster there; but each entry point costs 16 bytes of upload, 6% of the stream at 128
/// pairs (3% at 256; 13% at 64, which would take a smooth 2048² day's upload from 2.76×
/// the bytes read to about 3×).
pub const ENTRY_PAIRS: usize = 128;

/// The most blocks of the DC range whose DC one piece writes in zero runs.
pub const FILL_BLOCKS: u64 = 256;

/// Where the parse of a piece of a stream starts.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EntryPoint {
    /// The piece's first byte, from the start of the stream.
    pub byte: u32,
    /// The position the piece's first zero run counts from (`f · n + b`).
    pub position: u32,
    /// The DC of the block before `position` (0 before block 0), while in the DC range:
    /// the piece adds its DC differences onto it.
    pub dc: i32,
    /// The first position the piece writes: `position`, or a block inside the first
    /// pair's zero run where a long run of equal DC is shared out. The piece ends where
    /// the next one's `from` is (the stream's end for the last).
    pub from: u32,
}

/// What a scan saw of a stream's AC coefficients (the positions past the DC range): what
/// a decoder that keeps a block's terms sparse must make room for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AcTerms {
    /// Pairs whose value lies past the DC range: at least the non-zero AC coefficients.
    pub pairs: u64,
    /// Whether any of their values lies outside `i16`.
    pub wide: bool,
}

/// Scans the stream of `n` blocks at `buf[*pos..]`, pushing an entry point onto `out` for
/// every [`ENTRY_PAIRS`] pairs (the first at the stream's start), and moves `*pos` past
/// the stream; returns what it saw of the AC coefficients. Fails where
/// [`crate::plane::read_blocks`] fails.
pub fn scan(buf: &[u8], pos: &mut usize, n: usize, out: &mut Vec<EntryPoint>) -> Result<AcTerms> {
    let total = n as u64 * (N * N) as u64;
    // Positions and byte offsets are u32 on the GPU: a stream of more blocks than one
    // chunk can decode to is refused anyway (`read_blocks`).
    if n > crate::limits::MAX_CHUNK_DECODED as usize / (N * N) || total > u32::MAX as u64 {
        return Err(FormatError::Invalid(format!("{n} blocks in one stream")));
    }
    if n > 0 && buf.len() <= *pos {
        return Err(FormatError::Invalid(format!(
            "coefficient stream empty for {n} blocks"
        )));
    }
    let start = *pos;
    let (mut at, mut p, mut dc) = (start, 0u64, 0i32);
    let mut pairs = 0usize;
    let mut ac = AcTerms::default();
    // DC blocks the current piece writes.
    let mut fill = 0u64;
    let entry = |at: usize, p: u64, dc: i32, from: u64| -> Result<EntryPoint> {
        let byte = u32::try_from(at - start)
            .map_err(|_| FormatError::Invalid("coefficient stream over 4 GiB".into()))?;
        // (Positions are below `total`, checked above to fit in u32.)
        Ok(EntryPoint {
            byte,
            position: p as u32,
            dc,
            from: from as u32,
        })
    };
    loop {
        let pair = at;
        if pairs.is_multiple_of(ENTRY_PAIRS) {
            out.push(entry(pair, p, dc, p)?);
            fill = 0;
        }
        pairs += 1;
        let run = varint::get_u32(buf, &mut at)? as u64;
        if p < n as u64 && dc != 0 {
            // The run writes `dc` into its blocks of the DC range: a new piece starts
            // inside it whenever this one has written FILL_BLOCKS.
            let end = (p + run).min(n as u64);
            let mut b = p;
            while end - b > FILL_BLOCKS - fill {
                b += FILL_BLOCKS - fill;
                out.push(entry(pair, p, dc, b)?);
                fill = 0;
            }
            fill += end - b;
        }
        p += run;
        if p >= total {
            break;
        }
        let v = varint::get_i32(buf, &mut at)?;
        if p < n as u64 {
            dc = dc.wrapping_add(v);
        } else {
            ac.pairs += 1;
            ac.wide |= i16::try_from(v).is_err();
        }
        p += 1;
    }
    if p != total {
        return Err(FormatError::Invalid(format!(
            "zero run past the end of {n} blocks"
        )));
    }
    *pos = at;
    Ok(ac)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::{read_blocks, write_coefficients, Blocks};

    fn blocks(n: usize, seed: u32) -> Vec<[i32; 64]> {
        let mut s = seed;
        let mut next = move || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            s >> 8
        };
        (0..n)
            .map(|_| {
                let mut q = [0i32; 64];
                for _ in 0..[0, 1, 1, 3, 12][(next() % 5) as usize] {
                    q[(next() % 64) as usize] = (next() % 41) as i32 - 20;
                }
                if next() % 3 == 0 {
                    q[0] = (next() % 100_001) as i32 - 50_000;
                }
                q
            })
            .collect()
    }

    /// Parses a piece from `e` the way the GPU does: from `e.from` to `end` (the next
    /// piece's `from`, or the stream's end). Returns the DC blocks it wrote in zero runs.
    fn parse_piece(buf: &[u8], n: usize, e: EntryPoint, end: u64, q: &mut [[i32; 64]]) -> u64 {
        let (mut at, mut p, mut dc) = (e.byte as usize, e.position as u64, e.dc);
        let total = (n * 64) as u64;
        let mut filled = 0;
        loop {
            let run = varint::get_u32(buf, &mut at).unwrap() as u64;
            // Blocks of the DC range inside the run keep the running DC.
            for z in p.max(e.from as u64)..(p + run).min(n as u64).min(end) {
                q[z as usize][0] = dc;
                filled += (dc != 0) as u64;
            }
            p += run;
            if p >= total || p >= end {
                return filled;
            }
            let v = varint::get_i32(buf, &mut at).unwrap();
            // Frequency f is the zig-zag index.
            let (f, b) = ((p / n as u64) as usize, (p % n as u64) as usize);
            if f == 0 {
                dc = dc.wrapping_add(v);
                q[b][0] = dc;
            } else {
                q[b][f] = v;
            }
            p += 1;
            if p >= end {
                return filled;
            }
        }
    }

    /// Parses every piece, checking that none writes more than [`FILL_BLOCKS`] DCs in
    /// zero runs and that the pieces' `from` increase.
    fn parse_all(stream: &[u8], n: usize, entries: &[EntryPoint]) -> Vec<[i32; 64]> {
        let mut got = vec![[0i32; 64]; n];
        for (i, e) in entries.iter().enumerate() {
            let end = entries
                .get(i + 1)
                .map_or((n * 64) as u64, |x| x.from as u64);
            assert!(end >= e.from as u64, "entry {i}: {e:?}, next from {end}");
            let filled = parse_piece(stream, n, *e, end, &mut got);
            assert!(filled <= FILL_BLOCKS, "entry {i} wrote {filled} DCs");
        }
        got
    }

    /// The scan counts the AC coefficients (its pairs past the DC range: one per non-zero
    /// coefficient, as the encoder writes them) and says whether one needs more than 16
    /// bits; DC values, however large, count for neither.
    #[test]
    fn the_scan_counts_ac_terms_and_sees_a_wide_one() {
        let mut q = blocks(600, 7);
        let count = |q: &[[i32; 64]]| q.iter().flat_map(|b| &b[1..]).filter(|&&v| v != 0).count();
        let scanned = |q: &[[i32; 64]]| {
            let mut buf = Vec::new();
            write_coefficients(q, &mut buf);
            scan(&buf, &mut 0, q.len(), &mut Vec::new()).unwrap()
        };
        let ac = scanned(&q);
        assert_eq!(ac.pairs, count(&q) as u64);
        assert!(!ac.wide, "{ac:?}");
        q[5][0] = 1 << 20;
        assert!(!scanned(&q).wide);
        q[9][17] = -32_769;
        let ac = scanned(&q);
        assert!(ac.wide, "{ac:?}");
        assert_eq!(ac.pairs, count(&q) as u64);
    }

    #[test]
    fn pieces_parsed_from_the_entry_points_give_the_blocks() {
        for (n, seed) in [(0, 1), (1, 2), (7, 3), (500, 4), (3000, 5)] {
            let want = blocks(n, seed);
            let mut buf = vec![9, 9];
            write_coefficients(&want, &mut buf);
            buf.push(7);
            let mut pos = 2;
            let mut entries = Vec::new();
            scan(&buf, &mut pos, n, &mut entries).unwrap();
            assert_eq!(
                pos,
                buf.len() - 1,
                "{n} blocks: the scan ends where the stream does"
            );
            let stream = &buf[2..pos];
            let got = parse_all(stream, n, &entries);
            let mut check = Blocks::default();
            read_blocks(stream, &mut 0, n, &mut check).unwrap();
            for b in 0..n {
                assert_eq!(got[b], check.block(b), "{n} blocks: block {b}");
                assert_eq!(got[b], want[b], "{n} blocks: block {b}");
            }
            if n == 3000 {
                assert!(entries.len() > 10, "{} entry points", entries.len());
            }
        }
    }

    #[test]
    fn long_runs_of_equal_dc_are_shared_out() {
        // A smooth plane: the DC steps now and then and stays for long runs (one run
        // passes 5000 blocks), a few AC terms here and there.
        let n = 9000;
        let mut want = vec![[0i32; 64]; n];
        for (b, q) in want.iter_mut().enumerate() {
            q[0] = match b {
                0..=99 => 40,
                100..=5099 => -7,
                5100..=5102 => 3,
                _ => 12,
            };
            if b % 997 == 0 {
                q[5] = 2;
            }
        }
        let mut buf = Vec::new();
        write_coefficients(&want, &mut buf);
        let mut entries = Vec::new();
        scan(&buf, &mut 0, n, &mut entries).unwrap();
        // Every 256 blocks of a run, a piece: about 9000 / 256 of them, where the pairs
        // alone would give one.
        assert!(entries.len() >= 34, "{} entry points", entries.len());
        assert_eq!(parse_all(&buf, n, &entries), want);
    }

    #[test]
    fn the_scan_refuses_what_read_blocks_refuses() {
        let good = {
            let mut b = Vec::new();
            write_coefficients(&blocks(40, 9), &mut b);
            b
        };
        let mut cases: Vec<Vec<u8>> = vec![
            Vec::new(),
            good[..good.len() - 1].to_vec(),
            vec![0x80; 8],
            vec![0xFF, 0xFF, 0xFF, 0xFF, 0x7F],
        ];
        let mut long = good.clone();
        *long.last_mut().unwrap() = 5; // the final run goes past the end
        cases.push(long);
        for (i, c) in cases.iter().enumerate() {
            let r = scan(c, &mut 0, 40, &mut Vec::new());
            let b = read_blocks(c, &mut 0, 40, &mut Blocks::default());
            assert!(r.is_err() && b.is_err(), "case {i}: {r:?} {b:?}");
        }
        assert!(scan(&good, &mut 0, 40, &mut Vec::new()).is_ok());
        // No blocks: an empty final run only.
        assert!(scan(&[0], &mut 0, 0, &mut Vec::new()).is_ok());
        assert!(scan(&[1], &mut 0, 0, &mut Vec::new()).is_err());
    }

    #[test]
    fn on_arbitrary_bytes_the_scan_and_the_parse_agree() {
        // Short random streams of small varints (most bytes below 0x80 so that many
        // parse), and valid streams with one byte changed: the scan accepts exactly what
        // `read_blocks` accepts, and ends where it ends.
        let mut seed = 99u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let mut valid = Vec::new();
        write_coefficients(&blocks(30, 3), &mut valid);
        let (mut accepted, mut refused) = (0, 0);
        for case in 0..20_000 {
            let (buf, n) = if case % 2 == 0 {
                let len = 1 + (next() % 12) as usize;
                let buf: Vec<u8> = (0..len)
                    .map(|_| {
                        if next() % 8 == 0 {
                            0x80 | next() as u8
                        } else {
                            (next() % 6) as u8
                        }
                    })
                    .collect();
                (buf, (next() % 3) as usize)
            } else {
                let mut buf = valid.clone();
                let at = next() as usize % buf.len();
                buf[at] = next() as u8;
                (buf, 30)
            };
            let (mut p1, mut p2) = (0, 0);
            let a = scan(&buf, &mut p1, n, &mut Vec::new());
            let b = read_blocks(&buf, &mut p2, n, &mut Blocks::default());
            assert_eq!(
                a.is_ok(),
                b.is_ok(),
                "{buf:?}, {n} blocks: {a:?} against {b:?}"
            );
            if a.is_ok() {
                assert_eq!(p1, p2, "{buf:?}, {n} blocks");
                accepted += 1;
            } else {
                refused += 1;
            }
        }
        assert!(
            accepted > 1000 && refused > 1000,
            "{accepted} accepted, {refused} refused"
        );
    }
}
