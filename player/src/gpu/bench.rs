//! The GPU decode alone, for `vbim bench decode --gpu`.

use super::Gpu;
use crate::decoder::SegmentData;

/// The GPU decode alone, for `vbim bench decode --gpu`: boxes filled by a decoder without
/// a device, decoded one after another on a GPU of the stream's size.
pub struct GpuDecoder(Gpu);

impl GpuDecoder {
    /// GPU state for the stream `h` describes.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, h: &vbim_format::Header) -> Self {
        let mut gpu = Gpu::for_stream(device, queue, h);
        gpu.marks = crate::marks::Marks::new(device);
        GpuDecoder(gpu)
    }

    /// The GPU time between the marks of the last decode, each to the pass it ends (ns;
    /// empty unless the device has timestamps inside passes: [`timing_device`]). Call it
    /// after each [`GpuDecoder::decode`]: the query set holds one decode's marks.
    pub fn pass_times(&mut self) -> Vec<(&'static str, f64)> {
        let g = &self.0;
        g.marks
            .as_ref()
            .map_or_else(Vec::new, |m| m.read(&g.device, &g.queue))
    }

    /// Decodes `seg` (its keyframes and bubble planes), waits for the GPU and returns the
    /// wall-clock time from recording to completion.
    pub fn decode(&mut self, seg: &SegmentData) -> std::time::Duration {
        let t = std::time::Instant::now();
        let mut enc = self.0.device.create_command_encoder(&Default::default());
        if self.0.marks.is_some() {
            // A first mark, so that the time before the decode is not counted.
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.0.mark(&mut pass, crate::marks::START);
        }
        self.0.decode(&mut enc, seg, true);
        self.0.queue.submit([enc.finish()]);
        self.0.wait();
        t.elapsed()
    }
}
