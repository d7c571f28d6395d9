//! GPU timestamps between the decode's dispatches, for `vbim bench decode --gpu`: where a
//! segment's GPU time goes, pass by pass. Only on a device with timestamps inside passes
//! ([`NEEDS`]); the player itself never asks for them.

use std::cell::RefCell;

/// The features the marks need.
pub const NEEDS: wgpu::Features =
    wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES);

/// The label of the mark a decode starts with (no time is counted to it).
pub const START: &str = "start";

/// Marks one decode can hold between two reads: a dispatch writes one (a segment of
/// degree 4 at 3 channels, in parts, with a long keyframe chain stays far below), so the
/// marks are read after every decode.
const CAPACITY: u32 = 4096;

pub(crate) struct Marks {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    /// The label of each mark written since the last [`Marks::read`].
    labels: RefCell<Vec<&'static str>>,
}

impl Marks {
    /// Marks on `device`, if it has [`NEEDS`].
    pub fn new(device: &wgpu::Device) -> Option<Marks> {
        if !device.features().contains(NEEDS) {
            return None;
        }
        let set = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("vbim decode marks"),
            ty: wgpu::QueryType::Timestamp,
            count: CAPACITY,
        });
        let resolved = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vbim decode marks, resolved"),
            size: CAPACITY as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(Marks {
            set,
            resolved,
            labels: RefCell::new(Vec::new()),
        })
    }

    /// A timestamp once what `pass` recorded so far is done: the time since the mark
    /// before goes to `label`.
    pub fn mark(&self, pass: &mut wgpu::ComputePass, label: &'static str) {
        let mut labels = self.labels.borrow_mut();
        let i = labels.len() as u32;
        if i < CAPACITY {
            pass.write_timestamp(&self.set, i);
            labels.push(label);
        }
    }

    /// Reads the marks written by work already submitted and waited for, and forgets
    /// them: the GPU time between consecutive marks, each to its label, in ns.
    pub fn read(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Vec<(&'static str, f64)> {
        let labels = std::mem::take(&mut *self.labels.borrow_mut());
        let n = labels.len() as u32;
        if n < 2 {
            return Vec::new();
        }
        let mut enc = device.create_command_encoder(&Default::default());
        enc.resolve_query_set(&self.set, 0..n, &self.resolved, 0);
        queue.submit([enc.finish()]);
        let raw = crate::readback::read_buffer(device, queue, &self.resolved);
        let ticks: Vec<u64> = bytemuck::cast_slice::<u8, u64>(&raw[..n as usize * 8]).to_vec();
        let period = queue.get_timestamp_period() as f64;
        labels
            .iter()
            .enumerate()
            .skip(1)
            // A decode's first mark: the time before it is the CPU's, between submissions.
            .filter(|&(_, &label)| label != START)
            .map(|(i, &label)| {
                let ns = ticks[i].saturating_sub(ticks[i - 1]) as f64 * period;
                (label, ns)
            })
            .collect()
    }
}
