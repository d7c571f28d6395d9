//! `vbim play FILE --scene S` with a display: a window (winit) presenting the terrain
//! scene through a wgpu surface. Not built yet: it needs winit and a display to test under
//! (Xvfb); until then it says so.

use std::path::Path;

use crate::cmd_play::Session;

pub fn run(_s: &Session, _scene: &Path, _size: (u32, u32)) -> Result<(), String> {
    Err("the windowed player is not in this build yet: use --headless --out DIR to render the scene to PNG frames".into())
}
