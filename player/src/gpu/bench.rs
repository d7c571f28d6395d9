//! The GPU decode alone, for `vbim bench decode --gpu`.

use super::Gpu;
use crate::decoder::SegmentData;

impl Gpu {
    /// Puts timestamps between the passes of every frame from now on (`vbim bench render
    /// --passes`), where the device has them; returns whether it does.
    pub fn time_passes(&mut self) -> bool {
        self.marks = crate::marks::Marks::new(&self.device);
        self.marks.is_some()
    }

    /// A frame's first mark (no time is counted to it), where passes are timed.
    pub fn mark_start(&self, enc: &mut wgpu::CommandEncoder) {
        if self.marks.is_some() {
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.mark(&mut pass, crate::marks::START);
        }
    }

    /// The GPU time between the marks written since the last call, each to the pass it
    /// ends (ns), once the work is done.
    pub fn read_marks(&self) -> Vec<(&'static str, f64)> {
        self.marks
            .as_ref()
            .map_or_else(Vec::new, |m| m.read(&self.device, &self.queue))
    }
}

/// A decode's wall-clock time, and each dispatch's pass and work ([`GpuDecoder::decode`]).
pub type DecodeTime = (std::time::Duration, Vec<(&'static str, u64)>);

/// The GPU decode alone, for `vbim bench decode --gpu`: boxes filled by a decoder without
/// a device, decoded one after another on a GPU of the stream's size.
pub struct GpuDecoder(Gpu);

impl GpuDecoder {
    /// GPU state for the stream `h` describes, decoding in the shape given (`None`: the
    /// adapter's, [`DecodeShape::for_adapter`]).
    ///
    /// [`DecodeShape::for_adapter`]: crate::DecodeShape::for_adapter
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        h: &vbim_format::Header,
        shape: Option<crate::DecodeShape>,
    ) -> Self {
        let shape =
            shape.unwrap_or_else(|| crate::DecodeShape::for_adapter(&device.adapter_info()));
        let mut gpu = Gpu::for_stream(device, queue, h, shape);
        gpu.marks = crate::marks::Marks::new(device);
        GpuDecoder(gpu)
    }

    /// GPU memory the decode state holds, bytes (what [`Player::gpu_bytes`] counts).
    ///
    /// [`Player::gpu_bytes`]: crate::Player::gpu_bytes
    pub fn gpu_bytes(&self) -> u64 {
        self.0.bytes()
    }

    /// The GPU time between the marks of the last decode, each to the pass it ends (ns;
    /// empty unless the device has timestamps inside passes: [`timing_device`](super::timing_device)). Call it
    /// after each [`GpuDecoder::decode`]: the query set holds one decode's marks.
    pub fn pass_times(&mut self) -> Vec<(&'static str, f64)> {
        self.0.read_marks()
    }

    /// Decodes `seg` (its keyframes and bubble planes), waits for the GPU and returns the
    /// wall-clock time from recording to completion, and each dispatch's pass and work in
    /// the pass's own unit ([`PassWeights`]), in the order of their marks. A segment that
    /// does not fit this device's bindings is refused as the player refuses it.
    ///
    /// [`PassWeights`]: crate::PassWeights
    pub fn decode(&mut self, seg: &SegmentData) -> Result<DecodeTime, String> {
        self.0.fits(seg)?;
        let t = std::time::Instant::now();
        let mut enc = self.0.device.create_command_encoder(&Default::default());
        // A first mark, so that the time before the decode is not counted.
        self.0.mark_start(&mut enc);
        let steps = self.0.decode(&mut enc, seg, true);
        self.0.queue.submit([enc.finish()]);
        self.0.wait();
        Ok((t.elapsed(), steps))
    }
}
