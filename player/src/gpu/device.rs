//! Opening a device without a window, for headless playback, the tests and the benches.

/// A device, its queue and what the adapter says of itself.
pub type Headless = (wgpu::Device, wgpu::Queue, wgpu::AdapterInfo);

/// Why no headless device could be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DeviceError {
    /// No adapter on the backends asked for.
    #[error(
        "no GPU adapter found on {backends:?} ({source}). On a machine without a GPU install \
         a software one: `apt-get install -y libvulkan1 mesa-vulkan-drivers` (Vulkan, \
         lavapipe) or `libegl1 libegl-mesa0 libgl1-mesa-dri` (OpenGL, llvmpipe)"
    )]
    NoAdapter {
        /// The backends that were searched.
        backends: wgpu::Backends,
        /// What wgpu said.
        #[source]
        source: wgpu::RequestAdapterError,
    },
    /// An adapter was found but refused a device of WebGPU's default limits.
    #[error("{adapter} ({backend:?}): cannot open a device: {source}")]
    Open {
        /// The adapter's name.
        adapter: String,
        /// Its backend.
        backend: wgpu::Backend,
        /// What wgpu said.
        #[source]
        source: wgpu::RequestDeviceError,
    },
}

/// Finds an adapter and opens a device without a window, on the backends `WGPU_BACKEND`
/// names (all of them by default). With no adapter, the error says what to install.
pub fn headless_device() -> Result<Headless, DeviceError> {
    open_headless(
        wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
        wgpu::Features::empty(),
    )
}

/// [`headless_device`] on `backends` alone (for example `wgpu::Backends::GL`, the backend
/// WebGL and older machines give), whatever `WGPU_BACKEND` says.
pub fn headless_device_on(backends: wgpu::Backends) -> Result<Headless, DeviceError> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.backends = backends;
    open_headless(desc, wgpu::Features::empty())
}

/// [`headless_device`] with GPU timestamps between dispatches where the adapter has them,
/// for `vbim bench decode --gpu`'s time per pass.
#[cfg(feature = "bench")]
pub fn timing_device() -> Result<Headless, DeviceError> {
    open_headless(
        wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
        crate::marks::NEEDS,
    )
}

/// A device with `wanted`'s features that the adapter has (the others are left out).
fn open_headless(
    desc: wgpu::InstanceDescriptor,
    wanted: wgpu::Features,
) -> Result<Headless, DeviceError> {
    let backends = desc.backends;
    let instance = wgpu::Instance::new(desc);
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
            .map_err(|source| DeviceError::NoAdapter { backends, source })?;
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("vbim"),
        required_features: wanted & adapter.features(),
        // WebGPU's defaults, not the adapter's maxima: what Bevy and browsers give.
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .map_err(|source| DeviceError::Open {
        adapter: info.name.clone(),
        backend: info.backend,
        source,
    })?;
    Ok((device, queue, info))
}
