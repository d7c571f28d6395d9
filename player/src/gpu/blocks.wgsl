// What the shaders that sum 8 × 8 DCT blocks share (put before decode.wgsl and
// reconstruct.wgsl): the tables, and a block's 64-bit set of coefficients visited in
// increasing zig-zag order. Each shader binds `tables` itself.

// The DCT basis T[k][n] (row k, sample n) and the zig-zag order, from the reference
// decoder's own tables, so that the GPU and the reference use the same f32 values.
struct Tables {
    basis: array<vec4<f32>, 16>,
    zigzag: array<vec4<u32>, 16>,
    // Per zig-zag index i and quad (qx, qy) of a block (texels 2qx, 2qx + 1 across and
    // 2qy, 2qy + 1 down), at 16 i + 4 qy + qx: (T[ky][2qy], T[ky][2qy + 1], T[kx][2qx],
    // T[kx][2qx + 1]) for the position (ky, kx) the index stands for, so that a quad's
    // term takes one load.
    quad: array<vec4<f32>, 1024>,
}

fn basis(k: u32, n: u32) -> f32 {
    let i = k * 8u + n;
    return tables.basis[i / 4u][i % 4u];
}

fn zigzag(i: u32) -> u32 {
    return tables.zigzag[i / 4u][i % 4u];
}

// A 64-bit set being visited in increasing order: the word still to visit, the high word
// after it, and the first bit's number in `bits` (0 or 32). One loop over the 64 bits:
// two nested loops, one per word, cost lavapipe more.
struct Bits {
    bits: u32,
    high: u32,
    base: u32,
}

fn bits_of(m: vec2<u32>) -> Bits {
    return Bits(m.x, m.y, 0u);
}

// The next set bit of `*s`, taken out of it; 64 when none is left.
fn next_bit(s: ptr<function, Bits>) -> u32 {
    if ((*s).bits == 0u) {
        if ((*s).high == 0u) {
            return 64u;
        }
        *s = Bits((*s).high, 0u, 32u);
    }
    let i = (*s).base + firstTrailingBit((*s).bits);
    (*s).bits = (*s).bits & ((*s).bits - 1u);
    return i;
}

