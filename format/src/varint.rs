//! Zig-zag LEB128 integers: how quantised coefficients are packed before zstd.

use crate::{FormatError, Result};

/// Appends `v` as a zig-zag LEB128 integer.
pub fn put_i32(out: &mut Vec<u8>, v: i32) {
    put_u32(out, ((v << 1) ^ (v >> 31)) as u32);
}

/// Plain LEB128 (for counts such as zero runs).
pub fn put_u32(out: &mut Vec<u8>, mut u: u32) {
    while u >= 0x80 {
        out.push((u as u8) | 0x80);
        u >>= 7;
    }
    out.push(u as u8);
}

/// Reads one plain LEB128 value at `*pos`, advancing it.
#[inline(always)]
pub fn get_u32(buf: &[u8], pos: &mut usize) -> Result<u32> {
    get_raw(buf, pos)
}

/// Reads one zig-zag varint at `*pos`, advancing it. Fails on a truncated or over-long value.
#[inline(always)]
pub fn get_i32(buf: &[u8], pos: &mut usize) -> Result<i32> {
    let u = get_raw(buf, pos)?;
    Ok(((u >> 1) as i32) ^ -((u & 1) as i32))
}

/// Most coefficients and runs fit in one byte: that case is inlined into the caller's loop,
/// the rest is an out-of-line call. The position goes to that call and comes back by
/// value: were its address to escape, the caller's position would live in memory, and
/// every read would wait on the store of the one before.
#[inline(always)]
fn get_raw(buf: &[u8], pos: &mut usize) -> Result<u32> {
    if let Some(&b) = buf.get(*pos) {
        if b & 0x80 == 0 {
            *pos += 1;
            return Ok(b as u32);
        }
    }
    let (u, next) = get_long(buf, *pos)?;
    *pos = next;
    Ok(u)
}

#[cold]
#[inline(never)]
fn get_long(buf: &[u8], mut pos: usize) -> Result<(u32, usize)> {
    let mut u: u32 = 0;
    for shift in (0..35).step_by(7) {
        let b = *buf
            .get(pos)
            .ok_or_else(|| FormatError::Invalid("coefficient stream ends early".into()))?;
        pos += 1;
        if shift == 28 && b > 0x0f {
            return Err(FormatError::Invalid("varint overflows 32 bits".into()));
        }
        u |= ((b & 0x7f) as u32) << shift;
        if b & 0x80 == 0 {
            return Ok((u, pos));
        }
    }
    unreachable!("the loop returns or fails by the fifth byte")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_extremes() {
        let vals = [0, 1, -1, 63, -64, 64, 1 << 20, i32::MAX, i32::MIN];
        let mut buf = Vec::new();
        for v in vals {
            put_i32(&mut buf, v);
        }
        let mut pos = 0;
        for v in vals {
            assert_eq!(get_i32(&buf, &mut pos).unwrap(), v);
        }
        assert_eq!(pos, buf.len());
        assert!(get_i32(&buf, &mut pos).is_err());
        let bad = [0xff, 0xff, 0xff, 0xff, 0x7f];
        assert!(get_i32(&bad, &mut 0).is_err());
    }
}
