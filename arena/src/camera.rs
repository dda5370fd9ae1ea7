//! Synthetic front camera: what one car's 640x480 camera sees of the arena, rendered by ray casting
//! through the same pinhole model the on-board vision uses (`vision::pinhole::CameraModel`).
//!
//! The scene: a floor with a 250 mm checker of two greys, the four walls of the 1.5 m x 2 m arena
//! (150 mm tall, light grey) in front of a dark backdrop, and the other cars as 100 x 50 x 50 mm dark
//! boxes each carrying an upright cylinder marker in its car's colour (`vision::colour`). Seeded
//! uniform noise is added to every channel. Frames come out in the frame-grabber pixel format and
//! can be published into a frame-grabber window, or saved as PNG with detections drawn on them.
//!
//! World coordinates are millimetres with the origin at the arena corner where tracking has its
//! origin (1 tracking unit = 2.5 mm): X across the 1.5 m width, Y along the 2 m length, Z up; yaw is
//! counter-clockwise from +X.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::io::Write;
use vision::blobs::Detections;
use vision::colour::{Rgb, MARKER_PALETTE};
use vision::frame::{FrameWindow, HeaderError, PixelFormat};
use vision::pinhole::{CameraModel, MarkerModel};
use vision::FrameGeometry;

/// Arena width (X), mm.
pub const ARENA_X_MM: f32 = 1500.0;
/// Arena length (Y), mm.
pub const ARENA_Y_MM: f32 = 2000.0;
/// Wall height, mm.
pub const WALL_HEIGHT_MM: f32 = 150.0;
/// Car body length, width and height, mm.
pub const CAR_BODY_MM: [f32; 3] = [100.0, 50.0, 50.0];
/// Millimetres per tracking unit.
pub const MM_PER_TRACKING_UNIT: f32 = 2.5;

const FLOOR_A: Rgb = Rgb::new(150, 140, 120);
const FLOOR_B: Rgb = Rgb::new(120, 115, 100);
const FLOOR_TILE_MM: f32 = 250.0;
const WALL: Rgb = Rgb::new(225, 225, 225);
const BACKDROP: Rgb = Rgb::new(40, 40, 48);
const CAR_BODY: Rgb = Rgb::new(70, 70, 70);

/// A car's pose on the arena floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarPose {
    /// Car ID; the marker colour is `MARKER_PALETTE[id % 8]`.
    pub id: u8,
    pub x_mm: f32,
    pub y_mm: f32,
    /// Radians counter-clockwise from +X.
    pub yaw_rad: f32,
}

impl CarPose {
    /// A pose from tracking units (2.5 mm) and a heading in milliradians.
    pub fn from_tracking(id: u8, x: u16, y: u16, heading_mrad: u16) -> Self {
        CarPose {
            id,
            x_mm: f32::from(x) * MM_PER_TRACKING_UNIT,
            y_mm: f32::from(y) * MM_PER_TRACKING_UNIT,
            yaw_rad: f32::from(heading_mrad) * 0.001,
        }
    }
}

/// Camera settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraConfig {
    /// Intrinsics, mounting height and tilt.
    pub model: CameraModel,
    /// Forward distance of the camera from the car's reference point, mm.
    pub forward_offset_mm: f32,
    /// The marker every car carries.
    pub marker: MarkerModel,
    /// Pixel format of the frames.
    pub format: PixelFormat,
    /// Noise amplitude: each channel gets a uniform offset in `-noise..=noise`.
    pub noise: u8,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            model: CameraModel::default(),
            forward_offset_mm: 40.0,
            marker: MarkerModel::default(),
            format: PixelFormat::Rgb332,
            noise: 12,
        }
    }
}

/// What went wrong producing or saving a frame.
#[derive(Debug)]
pub enum CameraError {
    /// The output slice is smaller than one frame.
    BufferTooSmall { needed: usize, got: usize },
    /// The frame-grabber window was rejected, or does not match the camera.
    Window(HeaderError),
    /// The window's width, height or format differs from the camera's.
    WindowMismatch,
    /// PNG encoding or writing failed.
    Png(png::EncodingError),
}

impl From<HeaderError> for CameraError {
    fn from(e: HeaderError) -> Self {
        CameraError::Window(e)
    }
}

impl From<png::EncodingError> for CameraError {
    fn from(e: png::EncodingError) -> Self {
        CameraError::Png(e)
    }
}

/// One car's camera: the per-pixel rays are computed once, the noise generator is seeded.
#[derive(Debug)]
pub struct SyntheticCamera {
    config: CameraConfig,
    /// Ray of each pixel centre in the car frame (forward, left, up), row-major.
    rays: Vec<[f32; 3]>,
    rng: ChaCha8Rng,
}

struct CarInView {
    colour: Rgb,
    cx: f32,
    cy: f32,
    cos: f32,
    sin: f32,
    /// Pixel rectangle (inclusive) that can show this car.
    u0: usize,
    u1: usize,
    v0: usize,
    v1: usize,
}

impl SyntheticCamera {
    pub fn new(config: CameraConfig, seed: u64) -> Self {
        let m = &config.model;
        let mut rays = Vec::with_capacity(usize::from(m.width) * usize::from(m.height));
        for v in 0..m.height {
            for u in 0..m.width {
                rays.push(m.ray(f32::from(u) + 0.5, f32::from(v) + 0.5));
            }
        }
        SyntheticCamera {
            config,
            rays,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    pub fn config(&self) -> &CameraConfig {
        &self.config
    }

    /// Shape of the frames this camera renders.
    pub fn geometry(&self) -> FrameGeometry {
        let m = &self.config.model;
        FrameGeometry::packed(m.width, m.height, self.config.format)
    }

    /// Camera position (x, y, z) in the world for a car at `pose`.
    pub fn camera_position(&self, pose: &CarPose) -> [f32; 3] {
        let (s, c) = pose.yaw_rad.sin_cos();
        let d = self.config.forward_offset_mm;
        [
            pose.x_mm + d * c,
            pose.y_mm + d * s,
            f32::from(self.config.model.height_mm),
        ]
    }

    /// Renders what the car at `viewer` sees into `out` (packed rows); `cars` may include the
    /// viewer itself, which is skipped by ID.
    pub fn render(
        &mut self,
        viewer: &CarPose,
        cars: &[CarPose],
        out: &mut [u8],
    ) -> Result<(), CameraError> {
        let geometry = self.geometry();
        let needed = geometry.frame_len();
        if out.len() < needed {
            return Err(CameraError::BufferTooSmall {
                needed,
                got: out.len(),
            });
        }
        let (w, h) = (usize::from(geometry.width), usize::from(geometry.height));
        let origin = self.camera_position(viewer);
        let (sin_y, cos_y) = viewer.yaw_rad.sin_cos();
        let in_view: Vec<CarInView> = cars
            .iter()
            .filter(|c| c.id != viewer.id)
            .filter_map(|c| self.car_in_view(origin, viewer, c))
            .collect();
        let radius = f32::from(self.config.marker.diameter_mm) * 0.5;
        let m_lo = f32::from(self.config.marker.bottom_mm);
        let m_hi = m_lo + f32::from(self.config.marker.height_mm);
        let [hl, hw, bh] = [CAR_BODY_MM[0] * 0.5, CAR_BODY_MM[1] * 0.5, CAR_BODY_MM[2]];
        let noise = i16::from(self.config.noise);
        let span = 2 * noise as u32 + 1;
        let bpp = geometry.format.bytes_per_pixel();
        for v in 0..h {
            let cars_on_row: Vec<&CarInView> =
                in_view.iter().filter(|c| c.v0 <= v && v <= c.v1).collect();
            for u in 0..w {
                let r = self.rays[v * w + u];
                let d = [
                    r[0] * cos_y - r[1] * sin_y,
                    r[0] * sin_y + r[1] * cos_y,
                    r[2],
                ];
                let (mut t_best, mut colour) = background(origin, d);
                for car in cars_on_row.iter().filter(|c| c.u0 <= u && u <= c.u1) {
                    // Ray in the car's frame.
                    let ox = origin[0] - car.cx;
                    let oy = origin[1] - car.cy;
                    let lox = ox * car.cos + oy * car.sin;
                    let loy = -ox * car.sin + oy * car.cos;
                    let ldx = d[0] * car.cos + d[1] * car.sin;
                    let ldy = -d[0] * car.sin + d[1] * car.cos;
                    if let Some(t) = slab_hit(
                        [lox, loy, origin[2]],
                        [ldx, ldy, d[2]],
                        [-hl, -hw, 0.0],
                        [hl, hw, bh],
                    ) {
                        if t < t_best {
                            t_best = t;
                            colour = CAR_BODY;
                        }
                    }
                    if let Some(t) =
                        cylinder_hit([lox, loy, origin[2]], [ldx, ldy, d[2]], radius, m_lo, m_hi)
                    {
                        if t < t_best {
                            t_best = t;
                            colour = car.colour;
                        }
                    }
                }
                let colour = if noise > 0 {
                    let n = self.rng.next_u32();
                    let jitter = |c: u8, b: u32| {
                        let off = ((n >> b) & 0x3FF) % span;
                        (i16::from(c) + off as i16 - noise).clamp(0, 255) as u8
                    };
                    Rgb::new(
                        jitter(colour.r, 0),
                        jitter(colour.g, 10),
                        jitter(colour.b, 20),
                    )
                } else {
                    colour
                };
                let i = (v * w + u) * bpp;
                match geometry.format {
                    PixelFormat::Rgb332 => out[i] = colour.to_rgb332(),
                    PixelFormat::Rgb565 => {
                        out[i..i + 2].copy_from_slice(&colour.to_rgb565().to_le_bytes())
                    }
                }
            }
        }
        Ok(())
    }

    /// Renders into the free buffer of a frame-grabber window and publishes it; returns the
    /// frame's sequence number.
    pub fn render_into_window(
        &mut self,
        window: &mut [u8],
        viewer: &CarPose,
        cars: &[CarPose],
        capture_us: u64,
    ) -> Result<u32, CameraError> {
        let mut win = FrameWindow::new_checked(window)?;
        let g = self.geometry();
        let hdr = *win.header();
        if hdr.width != g.width || hdr.height != g.height || hdr.format != g.format {
            return Err(CameraError::WindowMismatch);
        }
        let index = win.begin_write();
        let stride = hdr.stride as usize;
        let row = usize::from(g.width) * g.format.bytes_per_pixel();
        if stride == row {
            self.render(viewer, cars, win.buffer_mut(index))?;
        } else {
            let mut packed = vec![0u8; g.frame_len()];
            self.render(viewer, cars, &mut packed)?;
            let buf = win.buffer_mut(index);
            for (y, src) in packed.chunks_exact(row).enumerate() {
                buf[y * stride..y * stride + row].copy_from_slice(src);
            }
        }
        Ok(win.publish(index, capture_us))
    }

    fn car_in_view(&self, origin: [f32; 3], viewer: &CarPose, car: &CarPose) -> Option<CarInView> {
        let m = &self.config.model;
        let (s, c) = car.yaw_rad.sin_cos();
        let (vs, vc) = viewer.yaw_rad.sin_cos();
        let top = f32::from(self.config.marker.bottom_mm) + f32::from(self.config.marker.height_mm);
        let radius = f32::from(self.config.marker.diameter_mm) * 0.5;
        let ext = (CAR_BODY_MM[0] * 0.5).max(radius);
        let (w, h) = (usize::from(m.width), usize::from(m.height));
        let (mut u0, mut u1, mut v0, mut v1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for &(fx, fy) in &[(-1.0f32, -1.0f32), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            // Corners of the box (and marker) footprint, in world coordinates.
            let lx = fx * ext;
            let ly = fy * (CAR_BODY_MM[1] * 0.5).max(radius);
            let wx = car.x_mm + lx * c - ly * s - origin[0];
            let wy = car.y_mm + lx * s + ly * c - origin[1];
            for z in [0.0, top] {
                // Into the viewer's car frame (forward, left, up) relative to the camera.
                let p = [wx * vc + wy * vs, -wx * vs + wy * vc, z - origin[2]];
                match m.project(p) {
                    Some((pu, pv)) => {
                        u0 = u0.min(pu);
                        u1 = u1.max(pu);
                        v0 = v0.min(pv);
                        v1 = v1.max(pv);
                    }
                    // A corner behind the camera: test the whole image.
                    None => {
                        u0 = f32::MIN;
                        u1 = f32::MAX;
                        v0 = f32::MIN;
                        v1 = f32::MAX;
                    }
                }
            }
        }
        if u1 < -1.0 || v1 < -1.0 || u0 > w as f32 || v0 > h as f32 {
            return None;
        }
        let clampu = |x: f32| x.clamp(0.0, (w - 1) as f32) as usize;
        let clampv = |x: f32| x.clamp(0.0, (h - 1) as f32) as usize;
        Some(CarInView {
            colour: MARKER_PALETTE[usize::from(car.id % 8)],
            cx: car.x_mm,
            cy: car.y_mm,
            cos: c,
            sin: s,
            u0: clampu(u0 - 1.0),
            u1: clampu(u1 + 1.0),
            v0: clampv(v0 - 1.0),
            v1: clampv(v1 + 1.0),
        })
    }
}

/// Nearest of floor, walls and backdrop along `d` from `o`.
fn background(o: [f32; 3], d: [f32; 3]) -> (f32, Rgb) {
    let tx = if d[0] > 0.0 {
        (ARENA_X_MM - o[0]) / d[0]
    } else if d[0] < 0.0 {
        -o[0] / d[0]
    } else {
        f32::INFINITY
    };
    let ty = if d[1] > 0.0 {
        (ARENA_Y_MM - o[1]) / d[1]
    } else if d[1] < 0.0 {
        -o[1] / d[1]
    } else {
        f32::INFINITY
    };
    let t_wall = tx.min(ty).max(0.0);
    if d[2] < 0.0 {
        let t_floor = -o[2] / d[2];
        if t_floor < t_wall {
            let x = o[0] + t_floor * d[0];
            let y = o[1] + t_floor * d[1];
            let tile =
                ((x / FLOOR_TILE_MM).floor() as i32 + (y / FLOOR_TILE_MM).floor() as i32) & 1;
            return (t_floor, if tile == 0 { FLOOR_A } else { FLOOR_B });
        }
    }
    let z = o[2] + t_wall * d[2];
    if (0.0..=WALL_HEIGHT_MM).contains(&z) {
        (t_wall, WALL)
    } else {
        (f32::INFINITY, BACKDROP)
    }
}

/// Entry distance of a ray into an axis-aligned box, if it enters in front of the origin.
fn slab_hit(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> Option<f32> {
    let mut t0 = 0.0f32;
    let mut t1 = f32::INFINITY;
    for i in 0..3 {
        if d[i].abs() < 1e-9 {
            if o[i] < lo[i] || o[i] > hi[i] {
                return None;
            }
        } else {
            let inv = 1.0 / d[i];
            let (a, b) = ((lo[i] - o[i]) * inv, (hi[i] - o[i]) * inv);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if t0 > t1 {
                return None;
            }
        }
    }
    Some(t0)
}

/// Entry distance of a ray into an upright cylinder on the local origin (side or top cap).
fn cylinder_hit(o: [f32; 3], d: [f32; 3], r: f32, z_lo: f32, z_hi: f32) -> Option<f32> {
    let a = d[0] * d[0] + d[1] * d[1];
    let mut best = None;
    if a > 1e-12 {
        let b = o[0] * d[0] + o[1] * d[1];
        let c = o[0] * o[0] + o[1] * o[1] - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            if t > 0.0 {
                let z = o[2] + t * d[2];
                if (z_lo..=z_hi).contains(&z) {
                    best = Some(t);
                }
            }
        }
    }
    if best.is_none() && d[2] < 0.0 && o[2] > z_hi {
        let t = (z_hi - o[2]) / d[2];
        let (x, y) = (o[0] + t * d[0], o[1] + t * d[1]);
        if x * x + y * y <= r * r {
            best = Some(t);
        }
    }
    best
}

/// Pixels of a frame as 8-bit RGB (for PNG and for people).
pub fn to_rgb8(frame: &[u8], geometry: &FrameGeometry) -> Result<Vec<u8>, CameraError> {
    let needed = geometry.frame_len();
    if frame.len() < needed {
        return Err(CameraError::BufferTooSmall {
            needed,
            got: frame.len(),
        });
    }
    let (w, h) = (usize::from(geometry.width), usize::from(geometry.height));
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            let c = match geometry.format {
                PixelFormat::Rgb332 => Rgb::from_rgb332(frame[y * geometry.stride + x]),
                PixelFormat::Rgb565 => {
                    let i = y * geometry.stride + 2 * x;
                    Rgb::from_rgb565(u16::from_le_bytes([frame[i], frame[i + 1]]))
                }
            };
            rgb.extend_from_slice(&[c.r, c.g, c.b]);
        }
    }
    Ok(rgb)
}

/// Draws each detection's bounding box (white, ringed in black) and centroid cross (black) on an
/// RGB8 image.
pub fn draw_detections(rgb: &mut [u8], width: usize, height: usize, detections: &Detections) {
    let mut put = |x: usize, y: usize, c: [u8; 3]| {
        if x < width && y < height {
            let i = (y * width + x) * 3;
            if let Some(px) = rgb.get_mut(i..i + 3) {
                px.copy_from_slice(&c);
            }
        }
    };
    for b in detections.blobs() {
        let (x0, y0, x1, y1) = (
            usize::from(b.min_x).saturating_sub(1),
            usize::from(b.min_y).saturating_sub(1),
            usize::from(b.max_x) + 1,
            usize::from(b.max_y) + 1,
        );
        // A white box with a black one around it shows on bright and dark backgrounds alike.
        for (x0, y0, x1, y1, c) in [
            (
                x0.saturating_sub(1),
                y0.saturating_sub(1),
                x1 + 1,
                y1 + 1,
                [0; 3],
            ),
            (x0, y0, x1, y1, [255; 3]),
        ] {
            for x in x0..=x1 {
                put(x, y0, c);
                put(x, y1, c);
            }
            for y in y0..=y1 {
                put(x0, y, c);
                put(x1, y, c);
            }
        }
        let (cx, cy) = b.centroid();
        let (cx, cy) = (cx.round() as usize, cy.round() as usize);
        for k in 0..=4 {
            put((cx + k).saturating_sub(2), cy, [0; 3]);
            put(cx, (cy + k).saturating_sub(2), [0; 3]);
        }
    }
}

/// Writes a frame as PNG with the detections drawn on it.
pub fn write_png<W: Write>(
    out: W,
    frame: &[u8],
    geometry: &FrameGeometry,
    detections: &Detections,
) -> Result<(), CameraError> {
    let mut rgb = to_rgb8(frame, geometry)?;
    let (w, h) = (usize::from(geometry.width), usize::from(geometry.height));
    draw_detections(&mut rgb, w, h, detections);
    let mut enc = png::Encoder::new(out, u32::from(geometry.width), u32::from(geometry.height));
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(&rgb)?;
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_and_cylinder_hits() {
        let t = slab_hit(
            [-100.0, 0.0, 25.0],
            [1.0, 0.0, 0.0],
            [-50.0, -25.0, 0.0],
            [50.0, 25.0, 50.0],
        );
        assert_eq!(t, Some(50.0));
        assert_eq!(
            slab_hit(
                [-100.0, 40.0, 25.0],
                [1.0, 0.0, 0.0],
                [-50.0, -25.0, 0.0],
                [50.0, 25.0, 50.0]
            ),
            None
        );
        let t = cylinder_hit([-100.0, 0.0, 70.0], [1.0, 0.0, 0.0], 20.0, 50.0, 90.0).unwrap();
        assert!((t - 80.0).abs() < 1e-3);
        assert_eq!(
            cylinder_hit([-100.0, 0.0, 95.0], [1.0, 0.0, 0.0], 20.0, 50.0, 90.0),
            None
        );
    }

    #[test]
    fn background_sees_floor_below_and_wall_ahead() {
        // From the arena centre, looking down at 45 degrees: floor at t = 70.
        let (t, c) = background([750.0, 1000.0, 70.0], [1.0, 0.0, -1.0]);
        assert_eq!(t, 70.0);
        assert!(c == FLOOR_A || c == FLOOR_B);
        // Horizontal: the wall 750 mm away.
        let (t, c) = background([750.0, 1000.0, 70.0], [1.0, 0.0, 0.0]);
        assert_eq!((t, c), (750.0, WALL));
        // Upwards: over the wall.
        let (_, c) = background([750.0, 1000.0, 70.0], [1.0, 0.0, 0.5]);
        assert_eq!(c, BACKDROP);
    }
}
