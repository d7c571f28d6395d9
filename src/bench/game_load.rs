//! A stand-in for a game's own GPU work (`vbim bench render --game-load MS`): a compute
//! pass of about MS milliseconds submitted before each displayed frame, untimed. A game
//! keeps its GPU busy for most of each display period; a benchmark that submits only the
//! player's frame leaves the card idle for the rest of it, and a hardware GPU then lowers
//! its clock between frames (an H200's idled at 345 MHz of its 1980 MHz), which a frame of
//! many small dependent dispatches pays for more than the reference blend does.

/// The load's pipeline, its buffer and the loop count that takes about the time asked.
pub(super) struct GameLoad {
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    params: wgpu::Buffer,
    queue: wgpu::Queue,
    /// What the calibrated load took: the fastest of three submissions, to completion, ms.
    pub took_ms: f64,
}

/// One wave of a large GPU: 1024 workgroups of 256 invocations, a vec4 each.
const GROUPS: u32 = 1024;

const LOAD_WGSL: &str = r#"
struct P { n: u32 }
@group(0) @binding(0) var<storage, read_write> acc: array<vec4<f32>>;
@group(0) @binding(1) var<uniform> p: P;
@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    var v = acc[id.x];
    for (var i = 0u; i < p.n; i = i + 1u) {
        v = v * 0.9999 + vec4<f32>(0.0001);
    }
    acc[id.x] = v;
}
"#;

impl GameLoad {
    /// A load of about `ms` milliseconds on `device`, its loop count found by timing it
    /// (submission to completion, a few rounds); `None` for `ms` ≤ 0.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, ms: f64) -> Option<GameLoad> {
        if ms <= 0.0 {
            return None;
        }
        let pipeline = super::frame_gpu::compute_pipeline(device, "game load", LOAD_WGSL);
        let acc = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("game load"),
            size: GROUPS as u64 * 256 * 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("game load"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = super::frame_gpu::bind_group(
            device,
            "game load",
            &pipeline,
            &[acc.as_entire_binding(), params.as_entire_binding()],
        );
        let mut load = GameLoad {
            pipeline,
            group,
            params,
            queue: queue.clone(),
            took_ms: 0.0,
        };
        // The fastest of three timed submissions of the load as it is set.
        let time = |load: &GameLoad| {
            (0..3)
                .map(|_| {
                    let t = std::time::Instant::now();
                    let mut enc = device.create_command_encoder(&Default::default());
                    load.record(&mut enc);
                    queue.submit([enc.finish()]);
                    let _ = device.poll(wgpu::PollType::wait_indefinitely());
                    t.elapsed().as_secs_f64() * 1e3
                })
                .fold(f64::INFINITY, f64::min)
        };
        // The loop count, scaled towards the time asked, five times over (a card's clock
        // climbs under the load itself).
        let mut n = 1024f64;
        for _ in 0..5 {
            load.set(n);
            n = (n * ms / time(&load).max(1e-3)).clamp(1.0, 4e9);
        }
        load.set(n);
        load.took_ms = time(&load);
        Some(load)
    }

    fn set(&self, n: f64) {
        let mut bytes = [0u8; 16];
        bytes[..4].copy_from_slice(&(n as u32).to_le_bytes());
        self.queue.write_buffer(&self.params, 0, &bytes);
    }

    /// The load, into `enc` (submitted before the player's frame).
    pub fn record(&self, enc: &mut wgpu::CommandEncoder) {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("game load"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.group, &[]);
        pass.dispatch_workgroups(GROUPS, 1, 1);
    }
}
