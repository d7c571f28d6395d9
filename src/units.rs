//! Units on the command line (docs/CONVENTIONS.md, "Units, flags and exit codes"): SI sizes and rates,
//! durations in ms, s, min or h, rationals for frame rates.

/// `500ms`, `4s`, `2min`, `1h` or a bare number of seconds → seconds.
pub fn parse_duration(s: &str) -> Result<f64, String> {
    let t = s.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix("min") {
        (n, 60.0)
    } else if let Some(n) = t.strip_suffix('h') {
        (n, 3600.0)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else {
        (t, 1.0)
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v * scale),
        _ => Err(format!(
            "duration {s:?} (expected e.g. 300ms, 4s, 2min, 1h)"
        )),
    }
}

/// `2GB`, `512MB`, `900kB`, `4096B` (SI) → bytes; `None` without a unit or a number.
fn si_bytes(t: &str) -> Option<f64> {
    let (num, scale) = [
        ("TB", 1e12),
        ("GB", 1e9),
        ("MB", 1e6),
        ("kB", 1e3),
        ("B", 1.0),
    ]
    .iter()
    .find_map(|&(unit, scale)| t.strip_suffix(unit).map(|n| (n, scale)))?;
    num.trim()
        .parse::<f64>()
        .ok()
        .map(|v| v * scale)
        .filter(|v| v.is_finite() && *v > 0.0)
}

/// `2GB`, `512MB`, `900kB`, `4096B` or a bare number of bytes (SI units) → bytes, at least 1.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    t.parse::<f64>()
        .ok()
        .or_else(|| si_bytes(t))
        .filter(|v| v.is_finite() && *v >= 1.0 && *v <= 1e15)
        .map(|v| v as u64)
        .ok_or_else(|| format!("size {s:?} (expected e.g. 2GB, 512MB or 900kB)"))
}

/// `--ring`: a size from 1 kB to 100 GB (SI units, or bytes).
pub fn parse_ring(s: &str) -> Result<u64, String> {
    parse_size(s)
        .ok()
        .filter(|v| (1000..=100_000_000_000).contains(v))
        .ok_or_else(|| format!("ring {s:?} (expected a size from 1kB to 100GB, e.g. 4MB)"))
}

/// `--memory-limit`: a size of at least 1 MB (SI units).
pub fn parse_memory_limit(s: &str) -> Result<vbim_format::Limits, String> {
    parse_size(s)
        .ok()
        .filter(|&v| v >= 1_000_000)
        .map(|memory| vbim_format::Limits { memory })
        .ok_or_else(|| format!("memory limit {s:?} (expected a size of at least 1MB, e.g. 4GB)"))
}

/// `--exposure`: a positive finite number up to 10⁶.
pub fn parse_exposure(s: &str) -> Result<f32, String> {
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0 && *v <= 1e6)
        .ok_or_else(|| format!("exposure {s:?} (expected a positive number up to 1e6)"))
}

/// `24/1`, `1/6` or `24` → (num, den).
pub fn parse_rate(s: &str) -> Result<(u32, u32), String> {
    vbim_bake::parse_rate(s)
}

/// A read rate: `2MB/s`, `500kB/s`, `1GB/s`, `800B/s` (SI), or `1.2x` (times the
/// stream's mean bit rate, resolved by the caller).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bandwidth {
    BytesPerSecond(f64),
    TimesMean(f64),
}

impl Bandwidth {
    /// Bytes per second for a file of `file_size` bytes lasting `duration_s`. A multiple of
    /// the mean rate resolves exactly as the header's read-ahead table does (rounded up), so
    /// that `1.2x` finds the table's 1.2× point.
    pub fn bytes_per_second(self, file_size: u64, duration_s: f64) -> u64 {
        match self {
            Bandwidth::BytesPerSecond(b) => b.round().max(1.0) as u64,
            Bandwidth::TimesMean(x) => vbim_format::buffer_model::rate_at(file_size, duration_s, x),
        }
    }
}

pub fn parse_bandwidth(s: &str) -> Result<Bandwidth, String> {
    let t = s.trim();
    let bad = || format!("bandwidth {s:?} (expected e.g. 2MB/s, 500kB/s or 1.2x)");
    if let Some(x) = t.strip_suffix('x') {
        return x
            .parse::<f64>()
            .ok()
            .filter(|v| *v > 0.0 && v.is_finite())
            .map(Bandwidth::TimesMean)
            .ok_or_else(bad);
    }
    let body = t.strip_suffix("/s").ok_or_else(bad)?;
    si_bytes(body)
        .map(Bandwidth::BytesPerSecond)
        .ok_or_else(bad)
}

/// `300ms@5s`: a stall of 300 ms every 5 s, the first at 5 s; `300ms@5s+2s`: the same with
/// the first at 2 s (a phase within the first period, to put a stall where the stream is
/// busiest).
pub fn parse_stall(s: &str) -> Result<vbim_player::Stall, String> {
    let bad =
        || format!("stall {s:?} (expected DURATION@PERIOD[+FIRST], e.g. 300ms@5s or 300ms@5s+2s)");
    let (d, rest) = s.split_once('@').ok_or_else(bad)?;
    let (p, first) = match rest.split_once('+') {
        Some((p, f)) => (p, Some(f)),
        None => (rest, None),
    };
    let (d, p) = (parse_duration(d)?, parse_duration(p)?);
    if d >= p || p <= 0.0 {
        return Err(format!(
            "stall {s:?}: the stall must be shorter than its period"
        ));
    }
    let first = first.map(parse_duration).transpose()?.unwrap_or(p);
    if first > p {
        return Err(format!(
            "stall {s:?}: the first stall must come within one period"
        ));
    }
    let ns = |v: f64| (v * 1e9).round() as u64;
    Ok(vbim_player::Stall {
        length_ns: ns(d),
        every_ns: ns(p),
        first_ns: ns(first),
    })
}

/// A duration flag (`500ms`, `4s`, `2min`), parsed once: nanoseconds, and the text it
/// was given as (what reports print).
#[derive(Clone, Debug, PartialEq)]
pub struct Span {
    ns: u64,
    text: String,
}

impl Span {
    /// `secs` seconds, written as such.
    pub fn from_secs(secs: f64) -> Span {
        Span {
            ns: (secs * 1e9) as u64,
            text: format!("{secs}s"),
        }
    }
    /// Nanoseconds.
    pub fn ns(&self) -> u64 {
        self.ns
    }
}

impl std::str::FromStr for Span {
    type Err = String;
    fn from_str(s: &str) -> Result<Span, String> {
        Ok(Span {
            ns: (parse_duration(s)? * 1e9) as u64,
            text: s.to_string(),
        })
    }
}

/// A duration flag of at most `max_s` seconds (`what` names the bound in the message).
fn span_at_most(s: &str, max_s: f64, what: &str) -> Result<Span, String> {
    let span: Span = s.parse()?;
    if span.ns as f64 > max_s * 1e9 {
        return Err(format!("{s:?} is longer than {what}"));
    }
    Ok(span)
}

/// `--duration`: more than nothing, at most 3 hours (records are kept per displayed frame).
pub fn parse_play_duration(s: &str) -> Result<Span, String> {
    let span = span_at_most(s, 3.0 * 3600.0, "3 hours")?;
    if span.ns == 0 {
        return Err(format!("{s:?}: nothing to play"));
    }
    Ok(span)
}

/// A catch-up window or a pre-roll margin: at most an hour.
pub fn parse_short_span(s: &str) -> Result<Span, String> {
    span_at_most(s, 3600.0, "an hour")
}

/// A weather switch at a time of the display's clock: `overcast@20s`.
#[derive(Clone, Debug)]
pub struct WeatherSwitch {
    pub weather: String,
    pub at: Span,
}

pub fn parse_weather_switch(s: &str) -> Result<WeatherSwitch, String> {
    let (weather, at) = s
        .split_once('@')
        .ok_or_else(|| format!("{s:?}: expected WEATHER@TIME, e.g. overcast@20s"))?;
    if !vbim_format::package::valid_name(weather) {
        return Err(format!("{s:?}: {weather:?} is not a weather's name"));
    }
    Ok(WeatherSwitch {
        weather: weather.to_string(),
        at: span_at_most(at, 3.0 * 3600.0, "3 hours")?,
    })
}

impl std::fmt::Display for Span {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

impl std::str::FromStr for Bandwidth {
    type Err = String;
    fn from_str(s: &str) -> Result<Bandwidth, String> {
        parse_bandwidth(s)
    }
}

impl std::fmt::Display for Bandwidth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Bandwidth::TimesMean(x) => write!(f, "{x}x"),
            Bandwidth::BytesPerSecond(b) if b >= 1e9 => write!(f, "{}GB/s", b / 1e9),
            Bandwidth::BytesPerSecond(b) if b >= 1e6 => write!(f, "{}MB/s", b / 1e6),
            Bandwidth::BytesPerSecond(b) if b >= 1e3 => write!(f, "{}kB/s", b / 1e3),
            Bandwidth::BytesPerSecond(b) => write!(f, "{b}B/s"),
        }
    }
}

/// A stall flag (`300ms@5s`, `300ms@5s+2s`), parsed once, with the text it was given as.
#[derive(Clone, Debug, PartialEq)]
pub struct StallSpec {
    /// The stall pattern.
    pub stall: vbim_player::Stall,
    text: String,
}

impl std::str::FromStr for StallSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<StallSpec, String> {
        Ok(StallSpec {
            stall: parse_stall(s)?,
            text: s.to_string(),
        })
    }
}

impl std::fmt::Display for StallSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

/// `--segment`: how segment lengths are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentSpec {
    /// `auto`: adaptive, up to the preset's maximum.
    Auto,
    /// `auto:N`: adaptive, up to N frames.
    AutoUpTo(u32),
    /// `N`: every segment N frames.
    Fixed(u32),
}

impl SegmentSpec {
    /// The encoder's setting, given the preset's (`auto` keeps its maximum).
    pub fn mode(self, preset: vbim_encoder::SegmentMode) -> vbim_encoder::SegmentMode {
        use vbim_encoder::SegmentMode;
        match (self, preset) {
            (SegmentSpec::Auto, SegmentMode::Auto { max }) => SegmentMode::Auto { max },
            (SegmentSpec::Auto, SegmentMode::Fixed(_)) => SegmentMode::Auto { max: 32 },
            (SegmentSpec::AutoUpTo(max), _) => SegmentMode::Auto { max },
            (SegmentSpec::Fixed(n), _) => SegmentMode::Fixed(n),
        }
    }
}

/// Parses `--segment`: `auto`, `auto:N` or a number of frames.
pub fn parse_segment(s: &str) -> Result<SegmentSpec, String> {
    let bad = || format!("{s:?}: expected auto, auto:N or a number of frames");
    if s == "auto" {
        return Ok(SegmentSpec::Auto);
    }
    if let Some(n) = s.strip_prefix("auto:") {
        return n.parse().map(SegmentSpec::AutoUpTo).map_err(|_| bad());
    }
    s.parse().map(SegmentSpec::Fixed).map_err(|_| bad())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("300ms").unwrap(), 0.3);
        assert_eq!(parse_duration("4s").unwrap(), 4.0);
        assert_eq!(parse_duration("2min").unwrap(), 120.0);
        assert_eq!(parse_duration("1h").unwrap(), 3600.0);
        assert!(parse_duration("-1s").is_err());
        assert!(parse_duration("fast").is_err());
    }

    #[test]
    fn bandwidths_and_stalls() {
        assert_eq!(
            parse_bandwidth("2MB/s").unwrap(),
            Bandwidth::BytesPerSecond(2e6)
        );
        assert_eq!(
            parse_bandwidth("500kB/s").unwrap(),
            Bandwidth::BytesPerSecond(5e5)
        );
        assert_eq!(parse_bandwidth("1.2x").unwrap(), Bandwidth::TimesMean(1.2));
        assert!(parse_bandwidth("2MiB").is_err());
        // 1.2 × 697 686.0 B/s = 837 223.2: the table's point is at 837 224 (rounded up), and
        // rounding to nearest once made `1.2x` fall back to the 1× point's larger ring.
        assert_eq!(
            Bandwidth::TimesMean(1.2).bytes_per_second(6_976_860, 10.0),
            837_224
        );
        assert_eq!(
            Bandwidth::BytesPerSecond(2e6).bytes_per_second(6_976_860, 10.0),
            2_000_000
        );
        assert_eq!(
            parse_stall("300ms@5s").unwrap(),
            vbim_player::Stall::every(300_000_000, 5_000_000_000)
        );
        assert_eq!(parse_stall("300ms@5s+2s").unwrap().first_ns, 2_000_000_000);
        assert_eq!(parse_stall("300ms@5s+0s").unwrap().first_ns, 0);
        assert!(parse_stall("5s@1s").is_err());
        assert!(parse_stall("300ms@5s+6s").is_err());
        assert!(parse_stall("300ms@5s+soon").is_err());
    }

    #[test]
    fn sizes_and_limits() {
        assert_eq!(parse_size("2GB").unwrap(), 2_000_000_000);
        assert_eq!(parse_size("900kB").unwrap(), 900_000);
        // `--ring` says 1 kB to 100 GB, and takes them as written.
        assert_eq!(parse_ring("1kB").unwrap(), 1000);
        assert_eq!(parse_ring("4096").unwrap(), 4096);
        assert!(parse_ring("999B").is_err() && parse_ring("101GB").is_err());
        assert_eq!(parse_size("4096").unwrap(), 4096);
        for bad in ["", "GB", "-1GB", "0", "1e30GB", "NaNMB", "2 GiB"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
        assert!(parse_memory_limit("999kB").is_err());
        assert_eq!(parse_memory_limit("8GB").unwrap().memory, 8_000_000_000);
        assert!(parse_exposure("1e39").is_err() && parse_exposure("0").is_err());
        assert!(parse_play_duration("0s").is_err() && parse_play_duration("4h").is_err());
        assert_eq!(parse_play_duration("3min").unwrap().ns(), 180_000_000_000);
    }

    #[test]
    fn typed_flags_keep_their_text_and_values() {
        let s: Span = "500ms".parse().unwrap();
        assert_eq!((s.ns(), s.to_string()), (500_000_000, "500ms".to_string()));
        assert_eq!(Span::from_secs(20.0).ns(), 20_000_000_000);
        for b in ["1.2x", "2MB/s", "500kB/s", "800B/s", "1.5GB/s"] {
            assert_eq!(b.parse::<Bandwidth>().unwrap().to_string(), b);
        }
        let st: StallSpec = "300ms@5s+2s".parse().unwrap();
        assert_eq!(
            (st.stall.first_ns, st.to_string()),
            (2_000_000_000, "300ms@5s+2s".into())
        );
    }
}
