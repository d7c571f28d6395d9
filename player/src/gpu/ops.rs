//! One step of a segment's decode ([`Op`]): a dispatch of a decode pass, a clear or the
//! upload, with the work it records (what the player shares out over frames).

use super::job::JOB_STRIDE;
use super::lanes::LanePass;
use crate::PassWeights;

/// What one step of a decode records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    /// The segment's streams into the stream buffer (from the box's staging buffer, or
    /// its words); the box is needed until this is recorded.
    Upload,
    /// The dense plane's masks and sets cleared for a part (`bytes` of them).
    Clear {
        bytes: u64,
    },
    /// An invocation per piece of a stream.
    Parse,
    /// A workgroup per piece.
    ParseWide,
    KeyAdd,
    KeyPack,
    /// A bubble set's tile degrees and term counter cleared.
    Degrees {
        offset: u64,
        bytes: u64,
    },
    /// A bubble plane's blocks gathered into its set.
    BubbleGather,
    /// A pass of a version 2 plane's decode (`lanes.wgsl`).
    Lane(LanePass),
}

/// One step of a segment's decode: a dispatch (or a clear) and what it costs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Op {
    pub(super) kind: Kind,
    /// The job's offset in the jobs buffer.
    pub(super) job: u32,
    /// The slice's offset in the slices buffer (slice k at k · [`JOB_STRIDE`]: its first
    /// workgroup, k · [`SLICE_GROUPS`]).
    pub(super) slice: u32,
    pub(super) groups: [u32; 3],
    /// A keyframe pass's plane (which view of the head it binds); a gather's bubble set
    /// (which term buffer it binds).
    pub(super) channel: u32,
    /// The work it records, in blocks (the time of a block's 64 texel sums of one term),
    /// each pass's units weighted by their measured cost
    /// ([`DecodeShape::weights`]; a parse's unit is an entry point, a gather's a block, a
    /// pack's 1/16 of a 32² region), plus on a GPU a fixed cost per step for its
    /// latency ([`DecodeShape::step_cost`]). What [`PlayerConfig::decode_budget`] counts.
    ///
    /// [`PlayerConfig::decode_budget`]: crate::PlayerConfig::decode_budget
    pub cost: u64,
    /// The work it records in its pass's own unit ([`PassWeights`] says which).
    pub(super) units: u64,
    /// Whether this op packs the head into a slot: once all of a pack's ops are
    /// recorded, the slot holds the head's keyframe.
    pub packs: bool,
}

impl Op {
    /// Whether recording it needs the segment's box (the upload).
    pub fn needs_box(&self) -> bool {
        self.kind == Kind::Upload
    }
}

impl Kind {
    /// The name of a dispatch's pass (its shader entry point; both parses are "parse"),
    /// as its timestamp is labelled; `None` for what is not a dispatch.
    pub(super) fn label(self) -> Option<&'static str> {
        Some(match self {
            Kind::Parse | Kind::ParseWide => "parse",
            Kind::KeyAdd => "key_add",
            Kind::KeyPack => "key_pack",
            Kind::BubbleGather => "bubble_gather",
            Kind::Lane(p) => p.label(),
            Kind::Upload | Kind::Clear { .. } | Kind::Degrees { .. } => return None,
        })
    }

    /// What one unit of the pass costs, in quarters of a block ([`PassWeights`]).
    pub(super) fn weight(self, w: &PassWeights) -> u32 {
        match self {
            Kind::Parse | Kind::ParseWide => w.parse,
            Kind::KeyAdd => w.key_add,
            Kind::KeyPack => w.key_pack,
            Kind::BubbleGather => w.bubble_gather,
            Kind::Lane(LanePass::Middle | LanePass::Blocks) => w.lane_word,
            Kind::Lane(_) => w.lane_block,
            Kind::Upload | Kind::Clear { .. } | Kind::Degrees { .. } => 0,
        }
    }
}

impl Op {
    pub(super) fn new(kind: Kind, job: u32, groups: [u32; 3], channel: u32, units: u64) -> Op {
        Op {
            kind,
            job,
            slice: 0,
            groups,
            channel,
            units,
            cost: 0,
            packs: false,
        }
    }

    /// A lanes pass of `groups` workgroups for each of `planes` planes, whose lane jobs
    /// lie from `job` on.
    pub(super) fn lanes(
        pass: LanePass,
        job: u32,
        [groups, planes]: [u32; 2],
        channel: u32,
        units: u64,
    ) -> Op {
        Op::new(Kind::Lane(pass), job, [groups, 1, planes], channel, units)
    }

    /// The dense plane's masks and sets cleared: `bytes` of them.
    pub(super) fn clear(bytes: u64, channel: u32) -> Op {
        Op::new(Kind::Clear { bytes }, 0, [0; 3], channel, 0)
    }

    /// The same op, in slice `k` of its pass.
    pub(super) fn in_slice(self, k: u32) -> Op {
        Op {
            slice: k * JOB_STRIDE as u32,
            ..self
        }
    }

    /// Whether it is a dispatch (recorded inside a compute pass).
    pub(super) fn dispatches(&self) -> bool {
        self.kind.label().is_some()
    }
}
