//! One decode pass's parameters, declared once: the macro below makes both the Rust
//! struct the player fills and the WGSL `struct Job` that `job.wgsl`, `parse.wgsl` and
//! `decode.wgsl` read, field by field in the same order, so the two cannot drift apart.

/// Declares a uniform struct of a decode pass, Rust and WGSL (its declaration in the
/// `wgsl` constant), from one list of fields, each with its Rust type and the WGSL type of
/// the same size and alignment; `fields` lists each field's name, bytes and WGSL type for
/// the layout test (`check_layout`).
macro_rules! uniform_struct {
    (
        $(#[doc = $sdoc:literal])* $struct:ident, $wgsl_const:ident, $fields:ident;
        $( $(#[doc = $doc:literal])* $name:ident : $rust:ty => $wgsl:literal ),* $(,)?
    ) => {
        $(#[doc = $sdoc])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub(super) struct $struct {
            $( $(#[doc = $doc])* pub $name: $rust, )*
        }

        /// The WGSL declaration of the struct, put before its shaders' source.
        pub(super) const $wgsl_const: &str = concat!(
            "struct ", stringify!($struct), " {\n",
            $( "    ", stringify!($name), ": ", $wgsl, ",\n", )*
            "}\n"
        );

        /// Each field's name, bytes and WGSL type (for the layout test).
        #[cfg(test)]
        pub(super) const $fields: &[(&str, usize, &str)] =
            &[$( (stringify!($name), std::mem::size_of::<$rust>(), $wgsl), )*];
    };
}
pub(super) use uniform_struct;

uniform_struct! {
    /// One decode pass's parameters, at a [`JOB_STRIDE`] stride in a uniform buffer
    /// bound with a dynamic offset.
    Job, JOB_WGSL, FIELDS;
    /// Quantiser step of the plane.
    step: f32 => "f32",
    /// Keyframe passes: the plane's channel; `key_pack`: the 16-bit layer it writes
    /// (slot · channels + plane). Bubble passes: the plane's layer.
    layer: u32 => "u32",
    /// The stream's first word.
    stream: u32 => "u32",
    /// The first entry point's first word.
    entries: u32 => "u32",
    /// How many entry points there are.
    count: u32 => "u32",
    /// Blocks the stream codes.
    blocks: u32 => "u32",
    /// The part [lo, hi) of the blocks this job keeps.
    lo: u32 => "u32",
    /// (See `lo`.)
    hi: u32 => "u32",
    /// A bubble plane's member spans: first word; 0 for a keyframe plane.
    members: u32 => "u32",
    /// The number of member spans.
    member_count: u32 => "u32",
    /// Workgroups per row of the dispatch (counts beyond 65 535 use more rows).
    groups_x: u32 => "u32",
    /// Blocks across a keyframe plane.
    blocks_x: u32 => "u32",
    /// Blocks across a tile.
    per: u32 => "u32",
    /// Tiles across the plane.
    tiles_x: u32 => "u32",
    /// Texels of the plane (pack passes).
    size: [u32; 2] => "vec2<u32>",
    /// `bubble_gather`: the first word of the plane's tile degrees in the degrees buffer.
    base: u32 => "u32",
    /// `key_add`: workgroups per group of 64 blocks, each visiting its share of them
    /// (1, 2, 4 … 64).
    split: u32 => "u32",
    /// `key_add`: 1 for an intra keyframe (its blocks written over the plane, those
    /// without a coefficient as zeros), 0 for a predicted one (added onto it).
    intra: u32 => "u32",
    /// `bubble_gather`: the plane's term k (2 …), which marks its tiles' degrees.
    term: u32 => "u32",
    /// `bubble_gather`: the word of the degrees buffer that counts the set's terms.
    counter: u32 => "u32",
    /// The first word of the part's masks in the ring of masks ([`super::plan::MaskRing`]).
    masks_at: u32 => "u32",
    /// The first word of the part's sets of blocks with a coefficient in the ring.
    sets_at: u32 => "u32",
    /// Where the part's block 0 lies in the dense plane, in blocks: 0, or for a plane of
    /// a batch parsed and gathered together, its place among the batch's (a multiple of
    /// 64, so that a group of 64 blocks is one plane's).
    dense_at: u32 => "u32",
}

/// Bytes between two jobs in the jobs buffer: WebGPU's default
/// `min_uniform_buffer_offset_alignment`.
pub(super) const JOB_STRIDE: u64 = 256;

/// The WGSL source of a decode shader: the `Job` declaration, what the decode passes
/// share (`job.wgsl`), then `body`.
pub(super) fn decode_source(body: &str) -> String {
    format!(
        "{JOB_WGSL}const BATCH_PLANES: u32 = {BATCH_PLANES}u;\n{}{body}",
        include_str!("job.wgsl")
    )
}

/// The most planes one dispatch covers (`workgroup_id.z`, each with its own job): a batch
/// of a segment's bubble planes ([`super::Gpu::plan_decode`]). The decode passes bind
/// this many jobs from a job's offset, so the jobs buffer holds that much past the last.
pub(super) const BATCH_PLANES: u32 = 16;

// job.wgsl pads a job to the stride with 160 bytes (naga's GL output ignored an
// `@size(256)` there, and a batch's second plane read the first's padding).
const _: () = assert!(std::mem::size_of::<Job>() + 160 == JOB_STRIDE as usize);

/// Bytes the decode passes' job binding covers: [`BATCH_PLANES`] jobs.
pub(super) const JOB_BINDING: u64 = BATCH_PLANES as u64 * JOB_STRIDE;

#[cfg(test)]
/// The WGSL struct has the Rust struct's fields in the same order at the same offsets:
/// every field is 4-byte scalars, an 8-byte vector or an array of 16-byte vectors at
/// an offset its alignment divides (WGSL's rule for these types), the Rust struct has
/// no padding, and its size is what a uniform binding of the WGSL struct needs.
pub(super) fn check_layout(fields: &[(&str, usize, &str)], size: usize) {
    let mut offset = 0;
    for &(name, bytes, wgsl) in fields {
        let (wgsl_bytes, align) = match wgsl {
            "f32" | "u32" | "i32" => (4, 4),
            "vec2<u32>" | "vec2<f32>" => (8, 8),
            "array<vec4<u32>, 2>" => (32, 16),
            other => panic!("{name}: WGSL type {other} not checked here"),
        };
        assert_eq!(bytes, wgsl_bytes, "{name}: Rust and WGSL sizes differ");
        assert_eq!(offset % align, 0, "{name}: WGSL would pad before it");
        offset += bytes;
    }
    assert_eq!(offset, size);
    assert!(offset as u64 <= JOB_STRIDE);
    assert!(
        offset.is_multiple_of(16),
        "a uniform struct's size is a multiple of 16"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wgsl_job_has_the_rust_layout() {
        check_layout(FIELDS, std::mem::size_of::<Job>());
        assert!(JOB_WGSL.starts_with("struct Job {\n    step: f32,\n"));
        let declared = |l: &str| l.trim_start().starts_with("struct Job");
        assert!(
            !include_str!("job.wgsl").lines().any(declared),
            "declared twice"
        );
    }
}
