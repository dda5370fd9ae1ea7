//! Pinhole camera model of the front camera: bearing and range to a marker of known size.
//!
//! Image axes: column `u` to the right, row `v` down, pixel `(i, j)` covering `[i, i+1) x [j, j+1)`,
//! principal point at the image centre. The focal length in pixels follows from the horizontal field
//! of view: `f = (width / 2) / tan(hfov / 2)`. The camera sits `height_mm` above the floor, pitched
//! down by `tilt_mrad`. Car frame: forward, left, up; bearing is counter-clockwise (to the left)
//! from straight ahead, in milliradians, as everywhere in the project.
//!
//! The trigonometry uses the compact `f32` functions of `maneuvers::fmath` (no `f64`, no `libm`:
//! the firmware has no FPU and little room for code); per blob, not per pixel.

use crate::blobs::Blob;
use maneuvers::fmath::{atan2 as atan2f, cos as cosf, sin as sinf, sqrt as sqrtf, tan as tanf};

/// Camera intrinsics and mounting.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CameraModel {
    pub width: u16,
    pub height: u16,
    /// Horizontal field of view, milliradians.
    pub hfov_mrad: u16,
    /// Height of the optical centre above the floor, mm.
    pub height_mm: f32,
    /// Downward pitch of the optical axis, milliradians (negative looks up).
    pub tilt_mrad: i16,
}

impl Default for CameraModel {
    /// The upper board's camera: 640x480, 60 degree horizontal view, 70 mm up, 50 mrad down.
    fn default() -> Self {
        CameraModel {
            width: 640,
            height: 480,
            hfov_mrad: 1047,
            height_mm: 70.0,
            tilt_mrad: 50,
        }
    }
}

/// The coloured marker every car carries: an upright cylinder.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MarkerModel {
    pub diameter_mm: f32,
    /// Bottom of the cylinder above the floor, mm.
    pub bottom_mm: f32,
    /// Cylinder height, mm.
    pub height_mm: f32,
}

impl Default for MarkerModel {
    /// 40 mm across and 40 mm tall, on top of a 50 mm tall car body.
    fn default() -> Self {
        MarkerModel {
            diameter_mm: 40.0,
            bottom_mm: 50.0,
            height_mm: 40.0,
        }
    }
}

/// Where a marker is, seen from the camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Observation {
    pub class: u8,
    /// Direction of the marker's axis, counter-clockwise from straight ahead, mrad.
    pub bearing_mrad: i32,
    /// Horizontal distance from the camera to the marker's axis, mm.
    pub range_mm: u32,
}

impl CameraModel {
    /// Focal length in pixels.
    pub fn focal_px(&self) -> f32 {
        let half = self.hfov_mrad as f32 * 0.0005;
        (self.width as f32 * 0.5) / tanf(half)
    }

    /// Direction (forward, left, up) of the ray through image point `(u, v)` in pixel units
    /// (`u = 320.0` is the centre line of a 640-wide image), not normalised.
    pub fn ray(&self, u: f32, v: f32) -> [f32; 3] {
        let f = self.focal_px();
        let x = (u - self.width as f32 * 0.5) / f;
        let y = (v - self.height as f32 * 0.5) / f;
        let t = self.tilt_mrad as f32 * 0.001;
        let (s, c) = (sinf(t), cosf(t));
        [c - y * s, -x, -y * c - s]
    }

    /// Image point of a point given in the car frame relative to the camera (forward, left, up);
    /// `None` behind the camera.
    pub fn project(&self, p: [f32; 3]) -> Option<(f32, f32)> {
        let t = self.tilt_mrad as f32 * 0.001;
        let (s, c) = (sinf(t), cosf(t));
        let z = p[0] * c - p[2] * s;
        if z <= 1e-3 {
            return None;
        }
        let x = -p[1];
        let y = -p[0] * s - p[2] * c;
        let f = self.focal_px();
        Some((
            self.width as f32 * 0.5 + f * x / z,
            self.height as f32 * 0.5 + f * y / z,
        ))
    }

    /// Bearing of image point `(u, v)`, radians counter-clockwise from straight ahead.
    pub fn bearing(&self, u: f32, v: f32) -> f32 {
        let r = self.ray(u, v);
        atan2f(r[1], r[0])
    }

    /// Bearing and range of a blob that is a whole marker. Range comes from the marker's angular
    /// width: the edge rays are tangent to the cylinder, so `range = (d / 2) / sin(width / 2)`.
    pub fn observe(&self, blob: &Blob, marker: &MarkerModel) -> Observation {
        let (_, cy) = blob.centroid();
        let v = cy + 0.5;
        let left = self.bearing(blob.min_x as f32, v);
        let right = self.bearing(blob.max_x as f32 + 1.0, v);
        let bearing = 0.5 * (left + right);
        let half = (0.5 * (left - right)).max(1e-4);
        let range = marker.diameter_mm * 0.5 / sinf(half);
        Observation {
            class: blob.class,
            bearing_mrad: (bearing * 1000.0) as i32,
            range_mm: range.clamp(0.0, u32::MAX as f32) as u32,
        }
    }

    /// Range from the image row of a point at a known height above the floor (for example the
    /// marker's centre); `None` when the ray does not come down (or up) to that height.
    pub fn range_from_row(&self, u: f32, v: f32, point_height_mm: f32) -> Option<f32> {
        let r = self.ray(u, v);
        let dz = point_height_mm - self.height_mm;
        if r[2] == 0.0 || (dz / r[2]) <= 0.0 {
            return None;
        }
        let k = dz / r[2];
        Some(k * sqrtf(r[0] * r[0] + r[1] * r[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn focal_length_from_field_of_view() {
        let m = CameraModel::default();
        // tan(30 degrees) = 0.57735: 320 / 0.57735 = 554.3.
        assert!((m.focal_px() - 554.3).abs() < 0.5, "{}", m.focal_px());
    }

    #[test]
    fn project_and_ray_agree() {
        let m = CameraModel::default();
        for p in [
            [1000.0, 0.0, 0.0],
            [800.0, 300.0, -70.0],
            [500.0, -200.0, 20.0],
        ] {
            let (u, v) = m.project(p).unwrap();
            let r = m.ray(u, v);
            let k = p[0] / r[0];
            for i in 0..3 {
                assert!((r[i] * k - p[i]).abs() < 0.5, "{p:?} {r:?}");
            }
        }
        assert_eq!(m.project([-100.0, 0.0, 0.0]), None);
    }

    #[test]
    fn centre_column_is_straight_ahead_and_left_is_positive() {
        let m = CameraModel::default();
        assert!(m.bearing(320.0, 240.0).abs() < 1e-6);
        assert!(m.bearing(0.0, 240.0) > 0.5);
        assert!((m.bearing(0.0, 240.0) - core::f32::consts::FRAC_PI_6).abs() < 0.02);
    }

    #[test]
    fn observation_of_a_projected_marker() {
        let m = CameraModel::default();
        let mk = MarkerModel::default();
        // Marker axis 1 m ahead and 0.3 m to the left, centre 0 mm above the camera height.
        let (cx, cl) = (1000.0f32, 300.0f32);
        let bearing = atan2f(cl, cx);
        let d = sqrtf(cx * cx + cl * cl);
        let half = (mk.diameter_mm * 0.5 / d).asin();
        let edge = |a: f32| m.project([a.cos() * d, a.sin() * d, 0.0]).unwrap().0;
        let (ul, ur) = (edge(bearing + half), edge(bearing - half));
        let blob = Blob {
            class: 1,
            area: 1,
            sum_x: 0,
            sum_y: 240,
            min_x: ul.round() as u16,
            max_x: ur.round() as u16 - 1,
            min_y: 240,
            max_y: 240,
        };
        let o = m.observe(&blob, &mk);
        assert!(
            (o.bearing_mrad - (bearing * 1000.0) as i32).abs() <= 3,
            "{o:?}"
        );
        assert!((o.range_mm as f32 - d).abs() < d * 0.05, "{o:?} {d}");
    }

    #[test]
    fn range_from_row_of_a_floor_point() {
        let m = CameraModel::default();
        let (u, v) = m.project([500.0, 0.0, -70.0]).unwrap();
        let r = m.range_from_row(u, v, 0.0).unwrap();
        assert!((r - 500.0).abs() < 1.0, "{r}");
        assert_eq!(m.range_from_row(320.0, 0.0, 0.0), None);
    }
}
