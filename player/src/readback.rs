//! Reading a GPU buffer back to the CPU, for the tests and the benchmarks.

/// Copies a buffer to the CPU: blocks until the GPU is done. For tests and benchmarks.
pub(crate) fn read_buffer(device: &wgpu::Device, queue: &wgpu::Queue, b: &wgpu::Buffer) -> Vec<u8> {
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("vbim readback"),
        size: b.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(b, 0, &out, 0, b.size());
    queue.submit(Some(enc.finish()));
    let slice = out.slice(..);
    slice.map_async(wgpu::MapMode::Read, |_| {});
    let _ = device.poll(wgpu::PollType::wait_indefinitely());
    slice.get_mapped_range().to_vec()
}
