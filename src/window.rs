//! `vbim play FILE --scene S` with a display: the terrain scene in a window (winit),
//! presented through a wgpu surface, with keys for pause, scrub and stall injection,
//! and the time of day, drift and bandwidth in the window title.
//!
//! Keys: Space pause · ←/→ scrub ∓/± 1 s · S stall the reader (toggle) ·
//! B halve / restore the bandwidth · W cycle a package's weathers (a cross-fade of
//! `--fade`) · Esc quit.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use vbim_player::{PackagePlayer, Throttle};
use vbim_scene::{orbit, Mesh, SceneRenderer, SkyTrack, View};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, KeyEvent, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

use crate::session::{mean_rate, scene_mesh, Session};

struct Gfx {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    device: wgpu::Device,
    queue: wgpu::Queue,
    player: PackagePlayer,
    renderer: SceneRenderer,
}

struct App {
    session: Session,
    scene_file: std::path::PathBuf,
    size: (u32, u32),
    exit_after: Option<u64>,
    instance: wgpu::Instance,
    gfx: Option<Gfx>,
    mesh: Option<Mesh>,
    /// The spheres standing on the terrain, lit by the light for objects.
    objects: Vec<vbim_scene::Object>,
    sky: SkyTrack,
    exposure: f32,
    paused: bool,
    stalled: bool,
    slow: bool,
    last: Option<Instant>,
    frames: u64,
    error: Option<String>,
}

impl App {
    fn init(&mut self, el: &ActiveEventLoop) -> Result<(), String> {
        let attrs = Window::default_attributes()
            .with_title("vbim")
            .with_inner_size(PhysicalSize::new(self.size.0, self.size.1));
        let window = Arc::new(el.create_window(attrs).map_err(|e| e.to_string())?);
        let surface = self
            .instance
            .create_surface(window.clone())
            .map_err(|e| e.to_string())?;
        let adapter =
            pollster::block_on(self.instance.request_adapter(&wgpu::RequestAdapterOptions {
                compatible_surface: Some(&surface),
                ..Default::default()
            }))
            .map_err(|e| format!("no GPU adapter for the window ({e})"))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("vbim window"),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| e.to_string())?;
        let inner = window.inner_size();
        let mut config = surface
            .get_default_config(&adapter, inner.width.max(1), inner.height.max(1))
            .ok_or("the surface does not work with this adapter")?;
        let caps = surface.get_capabilities(&adapter);
        config.format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .unwrap_or(config.format);
        surface.configure(&device, &config);
        let mut player = self.session.open_package(&device, &queue, true)?;
        if self.session.start > 0 {
            player.set_time(self.session.start_ns(player.lightmap_player().header())?);
        }
        let (mesh, hf) = scene_mesh(&self.scene_file)?;
        self.objects = vbim_scene::showcase(&mesh, &hf);
        let mut renderer = SceneRenderer::new(
            &device,
            &queue,
            &mesh,
            player.lightmap_view(),
            player.sky_view(),
            config.width,
            config.height,
            config.format,
        );
        if let Some(b) = player.irradiance_buffer() {
            renderer.set_objects(b, &self.objects);
        }
        self.mesh = Some(mesh);
        self.gfx = Some(Gfx {
            window,
            surface,
            config,
            device,
            queue,
            player,
            renderer,
        });
        Ok(())
    }

    fn redraw(&mut self) {
        let Some(g) = self.gfx.as_mut() else { return };
        let now = Instant::now();
        let dt = self.last.map_or(0, |l| (now - l).as_nanos() as u64);
        self.last = Some(now);
        let rec = g.player.advance(if self.paused { 0 } else { dt });
        let r = rec.lightmap;
        let mesh = self.mesh.as_ref().unwrap();
        let (eye, target) = orbit(g.player.ticks() as f32 * 1e-9 / 60.0, mesh);
        let frame = match g.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                g.surface.configure(&g.device, &g.config);
                return;
            }
            _ => return,
        };
        let view = frame.texture.create_view(&Default::default());
        g.renderer.render(
            &View {
                eye,
                target,
                fovy: 0.75,
                exposure: self.exposure,
                sky: self.sky.at(r.shown),
                detail: 0.5,
            },
            Some(&view),
        );
        frame.present();
        self.frames += 1;
        let n = g.player.lightmap_player().header().frame_count as f64;
        let hours = 24.0 * (r.shown.rem_euclid(n)) / n;
        let weather = match (&rec.switch, g.player.switching_to()) {
            (Some(s), _) if s.weight > 0.0 => {
                format!("{} → {} {:.0}%", g.player.weather(), s.to, s.weight * 100.0)
            }
            (_, Some(to)) => format!("{} → {to} (loading)", g.player.weather()),
            _ => g.player.weather().to_string(),
        };
        let totals = g.player.lightmap_player().totals();
        g.window.set_title(&format!(
            "vbim — {:02}:{:02}  {weather}  drift {:.2} frames  read {:.0} kB/s{}{}{}",
            hours as u32,
            ((hours.fract()) * 60.0) as u32,
            r.drift,
            totals.bytes_read as f64 / (g.player.ticks().max(1) as f64 * 1e-9) / 1e3,
            if self.paused { "  [paused]" } else { "" },
            if self.stalled { "  [stalled]" } else { "" },
            if self.slow { "  [½ bandwidth]" } else { "" },
        ));
    }

    fn key(&mut self, key: Key, el: &ActiveEventLoop) {
        let Some(g) = self.gfx.as_mut() else { return };
        let second = 1_000_000_000u64;
        match key {
            Key::Named(NamedKey::Escape) => el.exit(),
            Key::Named(NamedKey::Space) => self.paused = !self.paused,
            Key::Named(NamedKey::ArrowRight) => g.player.set_time(g.player.ticks() + second),
            Key::Named(NamedKey::ArrowLeft) => {
                g.player.set_time(g.player.ticks().saturating_sub(second))
            }
            Key::Character(c) if c.as_str() == "s" => {
                self.stalled = !self.stalled;
                g.player.set_throttle(if self.stalled {
                    Throttle {
                        rate: Some(1),
                        stall: None,
                    }
                } else {
                    self.session.throttle
                });
            }
            Key::Character(c) if c.as_str() == "w" => {
                // The weather after the one shown (or the one being switched to).
                let names: Vec<String> = g.player.weathers().map(str::to_string).collect();
                let current = g.player.switching_to().unwrap_or(g.player.weather());
                let i = names.iter().position(|n| n == current).unwrap_or(0);
                let next = names[(i + 1) % names.len()].clone();
                if let Err(e) = g.player.switch_weather(&next, self.session.fade_ns) {
                    eprintln!("{e}");
                }
            }
            Key::Character(c) if c.as_str() == "b" => {
                self.slow = !self.slow;
                let base = self.session.throttle;
                let rate = base
                    .rate
                    .unwrap_or((mean_rate(g.player.lightmap_player().header()) * 2.0) as u64);
                g.player.set_throttle(if self.slow {
                    Throttle {
                        rate: Some(rate / 2),
                        ..base
                    }
                } else {
                    base
                });
            }
            _ => {}
        }
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.gfx.is_none() {
            if let Err(e) = self.init(el) {
                self.error = Some(e);
                el.exit();
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                if let Some(g) = self.gfx.as_mut() {
                    g.config.width = size.width;
                    g.config.height = size.height;
                    g.surface.configure(&g.device, &g.config);
                    g.renderer = SceneRenderer::new(
                        &g.device,
                        &g.queue,
                        self.mesh.as_ref().unwrap(),
                        g.player.lightmap_view(),
                        g.player.sky_view(),
                        size.width,
                        size.height,
                        g.config.format,
                    );
                    if let Some(b) = g.player.irradiance_buffer() {
                        g.renderer.set_objects(b, &self.objects);
                    }
                }
            }
            WindowEvent::KeyboardInput {
                event:
                    KeyEvent {
                        logical_key,
                        state: ElementState::Pressed,
                        ..
                    },
                ..
            } => self.key(logical_key, el),
            WindowEvent::RedrawRequested => {
                self.redraw();
                if self.exit_after.is_some_and(|n| self.frames >= n) {
                    el.exit();
                }
                if let Some(g) = &self.gfx {
                    g.window.request_redraw();
                }
            }
            _ => {}
        }
    }
}

pub fn run(
    s: &Session,
    scene: &Path,
    size: (u32, u32),
    exit_after: Option<u64>,
) -> Result<(), String> {
    let el = EventLoop::new()
        .map_err(|e| format!("cannot open a window ({e}); without a display use --headless"))?;
    el.set_control_flow(ControlFlow::Poll);
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
        Box::new(el.owned_display_handle()),
    ));
    let (exposure, sky) = s.scene_look()?;
    let mut app = App {
        session: Session { ..s.clone() },
        scene_file: scene.to_path_buf(),
        size,
        exit_after,
        instance,
        gfx: None,
        mesh: None,
        objects: Vec::new(),
        sky,
        exposure,
        paused: false,
        stalled: false,
        slow: false,
        last: None,
        frames: 0,
        error: None,
    };
    el.run_app(&mut app).map_err(|e| e.to_string())?;
    if let Some(e) = app.error {
        return Err(e);
    }
    if let Some(mut g) = app.gfx.take() {
        g.player
            .stop(std::time::Duration::from_secs(10))
            .map_err(|e| e.to_string())?;
    }
    println!("window closed after {} frames", app.frames);
    Ok(())
}
