//! rANS with static 12-bit probabilities over 16-bit words: the entropy coder that format
//! 2's coefficient coding is designed around (BENCHMARKS.md, "A static coder a GPU can
//! decode"): version 2's keyframe and coefficient sections ([`plane2`](crate::plane2)).
//!
//! Why this shape, for a decoder in WGSL:
//! - **a 32-bit state renormalised by 16-bit words**: the state stays in [2¹⁶, 2³²), so a
//!   symbol reads at most one word and every step is one `u32` multiply, a shift and a
//!   table read — no 64-bit arithmetic, which WGSL lacks;
//! - **12-bit probabilities**: a decode table of 4096 entries per histogram, small enough
//!   for a few histograms in a workgroup's memory;
//! - **raw bits through the same state** (a value of k ≤ 12 bits is a symbol of
//!   probability 2⁻ᵏ), so a lane reads one word stream, not two;
//! - **hybrid-uint tokens** (JPEG XL's 4-2-0 configuration): values below 16 are their own
//!   token; larger ones a token for the exponent and the two bits below the leading one,
//!   then the rest raw. 128 tokens cover every `u32`.
//!
//! rANS is last in, first out: [`encode`] takes a lane's symbols in decoding order and
//! codes them backwards, so that [`Decoder`] reads them forwards. A lane's words start with
//! its final state (two words, high first).

use crate::{FormatError, Result};

/// Bits of a probability: every histogram's frequencies sum to 2¹².
pub const PROB_BITS: u32 = 12;
const SCALE: u32 = 1 << PROB_BITS;
/// The state's lower bound: the state lives in [LOW, LOW · 2¹⁶).
const LOW: u32 = 1 << 16;
/// Tokens of the hybrid-uint code: 16 direct values, then 4 per exponent from 4 to 31.
pub const TOKENS: usize = 16 + 28 * 4;

/// The token of `v`, its raw bits' count and their value.
pub fn hybrid_uint(v: u32) -> (usize, u32, u32) {
    if v < 16 {
        return (v as usize, 0, 0);
    }
    let n = 31 - v.leading_zeros();
    let m = (v >> (n - 2)) & 3;
    let raw = n - 2;
    (
        16 + (n as usize - 4) * 4 + m as usize,
        raw,
        v & ((1 << raw) - 1),
    )
}

/// How many raw bits follow `token`.
pub fn raw_bits_of(token: usize) -> u32 {
    if token < 16 {
        0
    } else {
        ((token - 16) / 4 + 4) as u32 - 2
    }
}

/// The value of `token` followed by `raw` (its [`raw_bits_of`] low bits).
pub fn hybrid_value(token: usize, raw: u32) -> u32 {
    if token < 16 {
        return token as u32;
    }
    let n = ((token - 16) / 4 + 4) as u32;
    let m = ((token - 16) % 4) as u32;
    ((4 | m) << (n - 2)) | raw
}

/// A histogram's frequencies, quantised to sum to 2¹² with every used token at least 1,
/// and the decode table they make.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Histogram {
    freq: Vec<u16>,
    /// The token whose frequency is what the others leave (not written).
    implied: u8,
    /// The token of each of the 4096 slots: shared by clones (a file's 96 histograms in its
    /// header are cloned with the header and into every chunk that uses them).
    slot: std::sync::Arc<[u8]>,
    /// Each token's frequency and first slot (the sum of the frequencies before it),
    /// frequency | first << 16 (0 past the last): what a decoded symbol's step reads, in
    /// one load from beside the token table. (A slot table of both, four bytes a slot,
    /// made the CPU's decode slower: 16 KiB a histogram leave the cache.)
    steps: [u32; TOKENS],
}

impl Histogram {
    /// The histogram of `counts` (one per token, at most [`TOKENS`]), its frequencies
    /// rounded to what [`Histogram::write`] can express; `None` if nothing was counted.
    pub fn from_counts(counts: &[u64]) -> Option<Histogram> {
        let total: u64 = counts.iter().sum();
        if total == 0 || counts.len() > TOKENS {
            return None;
        }
        let largest = (0..counts.len()).max_by_key(|&t| counts[t])?;
        let mut freq: Vec<u32> = counts
            .iter()
            .map(|&c| {
                if c == 0 {
                    0
                } else {
                    coarse(((c as f64 * SCALE as f64 / total as f64).round() as u32).max(1))
                }
            })
            .collect();
        // The largest takes what the others leave: it is what the rounding perturbs least.
        freq[largest] = 0;
        let rest: u32 = freq.iter().sum();
        if rest >= SCALE {
            // (Only with more tokens used than a histogram can give 1/4096 each, and not
            // then: 127 tokens at the coarse grid's worst stay below 4096 — but be safe.)
            return None;
        }
        freq[largest] = SCALE - rest;
        Some(Histogram::from_freq(
            freq.iter().map(|&f| f as u16).collect(),
            largest,
        ))
    }

    fn from_freq(freq: Vec<u16>, implied: usize) -> Histogram {
        let mut slot = vec![0u8; SCALE as usize];
        let mut steps = [0u32; TOKENS];
        let mut at = 0u16;
        for (t, &f) in freq.iter().enumerate() {
            slot[at as usize..(at + f) as usize].fill(t as u8);
            steps[t] = f as u32 | (at as u32) << 16;
            at += f;
        }
        Histogram {
            freq,
            implied: implied as u8,
            slot: slot.into(),
            steps,
        }
    }

    /// The frequency of `token` out of 4096 (0 if it is not used).
    pub fn frequency(&self, token: usize) -> u32 {
        self.freq.get(token).map_or(0, |&f| f as u32)
    }

    /// What a GPU decoder looks the state's slot up in: for each of the 4096 slots, its
    /// token, the token's frequency and the slot's offset from the token's first, packed
    /// as token | frequency << 7 | offset << 20 (7, 13 and 12 bits), so that a symbol's
    /// step is one load: the state x becomes frequency · (x >> 12) + offset.
    pub fn slot_table(&self) -> Vec<u32> {
        (self.slot.iter().enumerate())
            .map(|(slot, &t)| {
                let (f, first) = (
                    self.steps[t as usize] & 0xffff,
                    self.steps[t as usize] >> 16,
                );
                t as u32 | f << 7 | (slot as u32 - first) << 20
            })
            .collect()
    }

    /// Where `token`'s slots start among the 4096 (the sum of the frequencies before it).
    pub fn cumulative(&self, token: usize) -> u32 {
        match token < self.freq.len() {
            true => self.steps[token] >> 16,
            false => SCALE,
        }
    }

    /// Bits to code `token` with this histogram.
    pub fn cost(&self, token: usize) -> f64 {
        (SCALE as f64 / self.frequency(token) as f64).log2()
    }

    /// Appends the histogram to `out`: the token count and the implied token (the most
    /// frequent; 8 bits each), how many tokens are used (8 bits), then for each used token
    /// but the implied one its gap from the one before (Elias-gamma) and its frequency (4
    /// bits of exponent and at most 5 below the leading one). The implied token's
    /// frequency is what the others leave.
    pub fn write(&self, out: &mut BitWriter) {
        let largest = self.implied as usize;
        out.put(self.freq.len() as u32, 8);
        out.put(largest as u32, 8);
        let used = self.freq.iter().filter(|&&f| f > 0).count();
        out.put(used as u32 - 1, 8);
        let mut last = 0usize;
        for (t, &f) in self.freq.iter().enumerate() {
            if f == 0 || t == largest {
                continue;
            }
            out.gamma((t - last) as u32 + 1);
            last = t;
            let e = 31 - (f as u32).leading_zeros();
            out.put(e, 4);
            let keep = e.min(5);
            out.put(((f as u32) >> (e - keep)) & ((1 << keep) - 1), keep);
        }
    }

    /// Reads a histogram [`Histogram::write`] wrote, refusing one that does not describe
    /// frequencies summing to 4096 over at most [`TOKENS`] tokens.
    pub fn read(r: &mut BitReader) -> Result<Histogram> {
        let bad = |what: &str| FormatError::Invalid(format!("histogram: {what}"));
        let tokens = r.get(8)? as usize;
        let largest = r.get(8)? as usize;
        let used = r.get(8)? as usize + 1;
        if tokens == 0 || tokens > TOKENS || largest >= tokens || used > tokens {
            return Err(bad("token counts out of range"));
        }
        let mut freq = vec![0u16; tokens];
        let (mut last, mut sum) = (0usize, 0u32);
        for i in 0..used - 1 {
            let t = last + r.gamma()? as usize - 1;
            if (i > 0 && t <= last) || t >= tokens || t == largest {
                return Err(bad("tokens out of order"));
            }
            last = t;
            let e = r.get(4)?;
            if e >= PROB_BITS {
                return Err(bad("a frequency of 4096 or more"));
            }
            let keep = e.min(5);
            let f = ((1 << keep) | r.get(keep)?) << (e - keep);
            sum += f;
            if sum >= SCALE {
                return Err(bad("frequencies over 4096"));
            }
            freq[t] = f as u16;
        }
        freq[largest] = (SCALE - sum) as u16;
        Ok(Histogram::from_freq(freq, largest))
    }
}

/// `f` with only the bits [`Histogram::write`] keeps: the leading one and 5 below it.
fn coarse(f: u32) -> u32 {
    let e = 31 - f.leading_zeros();
    let drop = e.saturating_sub(5);
    (f >> drop) << drop
}

/// One symbol of a lane, in decoding order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Symbol {
    /// A token coded with a histogram.
    Token {
        /// Which of the histograms passed to [`encode`].
        histogram: u16,
        /// The token.
        token: u16,
    },
    /// Raw bits, each at probability 1/2.
    Raw {
        /// The bits, in the low `bits` bits.
        value: u32,
        /// How many (at most 32).
        bits: u8,
    },
}

/// Codes a lane's `symbols` (in the order a [`Decoder`] will read them) with
/// `histograms`, which must give every token coded a frequency. Returns the lane's words.
pub fn encode(symbols: &[Symbol], histograms: &[Histogram]) -> Vec<u16> {
    let mut x = LOW;
    let mut words = Vec::new();
    let mut put = |x: &mut u32, f: u32, c: u32| {
        debug_assert!(f > 0, "a symbol of frequency 0");
        // Keep the state below 2³² after the step: renormalise first. (In 64 bits: a
        // token of frequency 4096, a histogram's only one, never renormalises.)
        if *x as u64 >= (f as u64) << (32 - PROB_BITS) {
            words.push(*x as u16);
            *x >>= 16;
        }
        *x = ((*x / f) << PROB_BITS) + (*x % f) + c;
    };
    for s in symbols.iter().rev() {
        match *s {
            Symbol::Token { histogram, token } => {
                let h = &histograms[histogram as usize];
                let t = token as usize;
                put(&mut x, h.freq[t] as u32, h.cumulative(t));
            }
            Symbol::Raw { value, bits } => {
                // Pieces of at most 12 bits, the last piece coded first (it is read last).
                let mut pieces = Vec::new();
                let mut left = bits as u32;
                while left > 0 {
                    let k = left.min(PROB_BITS);
                    left -= k;
                    pieces.push((k, (value >> left) & ((1u32 << k) - 1)));
                }
                for &(k, v) in pieces.iter().rev() {
                    let f = 1 << (PROB_BITS - k);
                    put(&mut x, f, v << (PROB_BITS - k));
                }
            }
        }
    }
    words.push(x as u16);
    words.push((x >> 16) as u16);
    words.reverse();
    words
}

/// Reads a lane's symbols back, in the order they were passed to [`encode`].
pub struct Decoder<'a> {
    x: u32,
    words: &'a [u16],
    at: usize,
}

impl<'a> Decoder<'a> {
    /// Starts on a lane's words (its state first).
    pub fn new(words: &'a [u16]) -> Result<Decoder<'a>> {
        if words.len() < 2 {
            return Err(FormatError::Invalid(
                "rANS lane shorter than its state".into(),
            ));
        }
        let x = (words[0] as u32) << 16 | words[1] as u32;
        if x < LOW {
            return Err(FormatError::Invalid(format!("rANS state {x} below 2^16")));
        }
        Ok(Decoder { x, words, at: 2 })
    }

    #[inline(always)]
    fn step(&mut self, f: u32, c: u32) -> Result<()> {
        let slot = self.x & (SCALE - 1);
        self.x = f * (self.x >> PROB_BITS) + slot - c;
        if self.x < LOW {
            let w = *self
                .words
                .get(self.at)
                .ok_or_else(|| FormatError::Invalid("rANS lane ends early".into()))?;
            self.at += 1;
            self.x = self.x << 16 | w as u32;
        }
        Ok(())
    }

    /// The next token, coded with `h`.
    #[inline]
    pub fn token(&mut self, h: &Histogram) -> Result<usize> {
        let t = h.slot[(self.x & (SCALE - 1)) as usize] as usize;
        let e = h.steps[t & (TOKENS - 1)];
        self.step(e & 0xffff, e >> 16)?;
        Ok(t)
    }

    /// The next `bits` raw bits (at most 32).
    #[inline]
    pub fn raw(&mut self, bits: u32) -> Result<u32> {
        let mut v = 0u32;
        let mut left = bits;
        while left > 0 {
            let k = left.min(PROB_BITS);
            left -= k;
            let piece = (self.x & (SCALE - 1)) >> (PROB_BITS - k);
            self.step(1 << (PROB_BITS - k), piece << (PROB_BITS - k))?;
            v = if k == 32 { piece } else { (v << k) | piece };
        }
        Ok(v)
    }

    /// Checks that the lane was read to its end: every word used and the state back where
    /// the encoder started.
    pub fn finish(&self) -> Result<()> {
        if self.at != self.words.len() || self.x != LOW {
            return Err(FormatError::Invalid(format!(
                "rANS lane: {} of {} words read, state {} at the end",
                self.at,
                self.words.len(),
                self.x
            )));
        }
        Ok(())
    }
}

/// Bits appended to a byte vector, least significant first.
#[derive(Default)]
pub struct BitWriter {
    bytes: Vec<u8>,
    bits: u64,
    n: u32,
}

impl BitWriter {
    /// Appends the low `n` bits of `v` (n ≤ 32).
    pub fn put(&mut self, v: u32, n: u32) {
        let v = if n == 32 {
            v as u64
        } else {
            (v & ((1 << n) - 1)) as u64
        };
        self.bits |= v << self.n;
        self.n += n;
        while self.n >= 8 {
            self.bytes.push(self.bits as u8);
            self.bits >>= 8;
            self.n -= 8;
        }
    }

    /// Appends `v ≥ 1` as an Elias-gamma code: as many zeros as it has bits after the
    /// leading one, then its bits from the leading one down.
    pub fn gamma(&mut self, v: u32) {
        let n = 31 - v.leading_zeros();
        self.put(0, n);
        for i in (0..=n).rev() {
            self.put((v >> i) & 1, 1);
        }
    }

    /// Bits written so far.
    pub fn len_bits(&self) -> u64 {
        self.bytes.len() as u64 * 8 + self.n as u64
    }

    /// The bytes, the last one padded with zeros.
    pub fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            self.bytes.push(self.bits as u8);
        }
        self.bytes
    }
}

/// Reads what a [`BitWriter`] wrote.
pub struct BitReader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> BitReader<'a> {
    /// Starts at the first bit of `bytes`.
    pub fn new(bytes: &'a [u8]) -> BitReader<'a> {
        BitReader { bytes, at: 0 }
    }

    /// The next `n` bits (n ≤ 32).
    pub fn get(&mut self, n: u32) -> Result<u32> {
        let mut v = 0u32;
        for i in 0..n {
            let byte = *self
                .bytes
                .get(self.at / 8)
                .ok_or_else(|| FormatError::Invalid("bits past the end".into()))?;
            v |= (((byte >> (self.at % 8)) & 1) as u32) << i;
            self.at += 1;
        }
        Ok(v)
    }

    /// The next Elias-gamma code.
    pub fn gamma(&mut self) -> Result<u32> {
        let mut n = 0;
        while self.get(1)? == 0 {
            n += 1;
            if n > 31 {
                return Err(FormatError::Invalid(
                    "an Elias-gamma code over 32 bits".into(),
                ));
            }
        }
        let mut v = 1u32;
        for _ in 0..n {
            v = (v << 1) | self.get(1)?;
        }
        Ok(v)
    }

    /// Bits read so far.
    pub fn position(&self) -> usize {
        self.at
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed pseudo-random sequence (no dependency, the same on every machine).
    fn lcg(seed: &mut u64) -> u32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 33) as u32
    }

    #[test]
    fn hybrid_uint_round_trips_every_exponent() {
        for v in (0..70_000u32).chain([u32::MAX, u32::MAX - 1, 1 << 31, (1 << 31) - 1]) {
            let (t, n, raw) = hybrid_uint(v);
            assert!(t < TOKENS);
            assert_eq!(raw_bits_of(t), n, "{v}");
            assert_eq!(hybrid_value(t, raw), v, "{v}");
        }
    }

    #[test]
    fn symbols_and_raw_bits_round_trip_at_about_their_cost() {
        let mut seed = 5u64;
        // Two skewed histograms over 40 tokens.
        let counts: Vec<Vec<u64>> = (0..2)
            .map(|h| {
                (0..40u64)
                    .map(|t| {
                        if t % (h + 2) == 0 {
                            0
                        } else {
                            1000 >> (t / 3).min(9)
                        }
                    })
                    .collect()
            })
            .collect();
        let hs: Vec<Histogram> = counts
            .iter()
            .map(|c| Histogram::from_counts(c).unwrap())
            .collect();
        // Sample symbols from each histogram's own frequencies, with raw bits between.
        let mut symbols = Vec::new();
        let mut ideal = 0.0;
        for i in 0..50_000 {
            let h = i % 2;
            let r = lcg(&mut seed) % 4096;
            let t = (0..40)
                .find(|&t| r < hs[h].cumulative(t) + hs[h].freq[t] as u32)
                .unwrap();
            ideal += hs[h].cost(t);
            symbols.push(Symbol::Token {
                histogram: h as u16,
                token: t as u16,
            });
            if i % 7 == 0 {
                let bits = (lcg(&mut seed) % 33) as u8;
                let value = lcg(&mut seed) << 1 | (lcg(&mut seed) & 1);
                ideal += bits as f64;
                symbols.push(Symbol::Raw { value, bits });
            }
        }
        let words = encode(&symbols, &hs);
        let mut d = Decoder::new(&words).unwrap();
        for s in &symbols {
            match *s {
                Symbol::Token { histogram, token } => {
                    assert_eq!(d.token(&hs[histogram as usize]).unwrap(), token as usize)
                }
                Symbol::Raw { value, bits } => {
                    let mask = if bits == 32 {
                        u32::MAX
                    } else {
                        (1u32 << bits) - 1
                    };
                    assert_eq!(d.raw(bits as u32).unwrap(), value & mask)
                }
            }
        }
        d.finish().unwrap();
        // Within 0.2% of the ideal length, plus the final state.
        let got = (words.len() * 16) as f64;
        assert!(got < ideal * 1.002 + 32.0, "{got} bits against {ideal:.0}");
    }

    #[test]
    fn a_certain_token_costs_nothing() {
        let h = Histogram::from_counts(&[0, 0, 9]).unwrap();
        assert_eq!(h.frequency(2), 4096);
        let symbols = vec![
            Symbol::Token {
                histogram: 0,
                token: 2
            };
            10_000
        ];
        let words = encode(&symbols, std::slice::from_ref(&h));
        assert_eq!(words.len(), 2);
        let mut d = Decoder::new(&words).unwrap();
        for _ in 0..10_000 {
            assert_eq!(d.token(&h).unwrap(), 2);
        }
        d.finish().unwrap();
    }

    #[test]
    fn an_empty_lane_is_its_state_and_a_short_one_is_refused() {
        let words = encode(&[], &[]);
        assert_eq!(words.len(), 2);
        Decoder::new(&words).unwrap().finish().unwrap();
        assert!(Decoder::new(&words[..1]).is_err());
        let h = Histogram::from_counts(&[1, 1]).unwrap();
        let words = encode(
            &[Symbol::Raw { value: 5, bits: 30 }; 8],
            std::slice::from_ref(&h),
        );
        let mut d = Decoder::new(&words[..words.len() - 1]).unwrap();
        let e = (0..8).try_for_each(|_| d.raw(30).map(|_| ()));
        assert!(e.is_err() || d.finish().is_err());
    }

    #[test]
    fn histograms_round_trip_through_their_bits_and_bad_ones_are_refused() {
        let mut seed = 9u64;
        for n in [0usize, 1, 2, 5, 40, TOKENS - 1] {
            let counts: Vec<u64> = (0..n)
                .map(|_| {
                    let r = lcg(&mut seed);
                    if r.is_multiple_of(3) {
                        0
                    } else {
                        (r % 100_000) as u64
                    }
                })
                .chain([7])
                .collect();
            let h = Histogram::from_counts(&counts).unwrap();
            assert_eq!(h.freq.iter().map(|&f| f as u32).sum::<u32>(), 4096);
            for (t, &c) in counts.iter().enumerate() {
                assert_eq!(c > 0, h.frequency(t) > 0, "token {t}");
            }
            let mut w = BitWriter::default();
            h.write(&mut w);
            let bytes = w.finish();
            let mut r = BitReader::new(&bytes);
            assert_eq!(Histogram::read(&mut r).unwrap(), h);
            assert!(r.position() <= bytes.len() * 8);
        }
        // Frequencies that overflow 4096, tokens out of order, a truncated table.
        let mut w = BitWriter::default();
        w.put(4, 8);
        w.put(0, 8);
        w.put(2, 8);
        for t in [2u32, 1] {
            w.gamma(t);
            w.put(11, 4);
            w.put(31, 5);
        }
        let bytes = w.finish();
        assert!(Histogram::read(&mut BitReader::new(&bytes)).is_err());
        assert!(Histogram::read(&mut BitReader::new(&bytes[..2])).is_err());
    }
}
