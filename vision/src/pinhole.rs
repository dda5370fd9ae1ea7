//! Pinhole camera model of the front camera: bearing and range to a marker of known size.
//!
//! Image axes: column `u` to the right, row `v` down, pixel `(i, j)` covering `[i, i+1) x [j, j+1)`,
//! principal point at the image centre. The focal length in pixels follows from the horizontal field
//! of view: `f = (width / 2) / tan(hfov / 2)`. The camera sits `height_mm` above the floor, pitched
//! down by `tilt_mrad`. Car frame: forward, left, up; bearing is counter-clockwise (to the left)
//! from straight ahead, in milliradians, as everywhere in the project.
//!
//! What the firmware runs, [`CameraModel::observe`], is fixed point (`maneuvers::fixed`: image
//! coordinates in 1/16 pixel, binary angles, Q14 sines): the firmware has no FPU and little
//! room for code. The `f32` functions ([`CameraModel::ray`], [`CameraModel::project`],
//! [`CameraModel::bearing`], [`CameraModel::range_from_row`]) are for the host (the arena's
//! synthetic camera, tests), with the compact functions of `maneuvers::fmath`.

use crate::blobs::Blob;
use maneuvers::fixed::{atan2, from_mrad, mul_q14, sin_cos, to_mrad};
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
    pub height_mm: u16,
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
            height_mm: 70,
            tilt_mrad: 50,
        }
    }
}

/// The coloured marker every car carries: an upright cylinder.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MarkerModel {
    pub diameter_mm: u16,
    /// Bottom of the cylinder above the floor, mm.
    pub bottom_mm: u16,
    /// Cylinder height, mm.
    pub height_mm: u16,
}

impl Default for MarkerModel {
    /// 40 mm across and 40 mm tall, on top of a 50 mm tall car body.
    fn default() -> Self {
        MarkerModel {
            diameter_mm: 40,
            bottom_mm: 50,
            height_mm: 40,
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

    /// Focal length in 1/16 pixel: `width / 2 * cot(hfov / 2)`.
    fn focal_q4(&self) -> i32 {
        let (s, c) = sin_cos(from_mrad(i32::from(self.hfov_mrad)) / 2);
        // cot in Q14: below 2^28 / 1 even for a field of view of a few mrad.
        mul_q14(i32::from(self.width) * 8, (c << 14) / s.max(1))
    }

    /// Bearing of image point `(u, v)` given in 1/16 pixel, as a binary angle (65 536 per
    /// turn): [`CameraModel::bearing`] in fixed point.
    fn bearing_q4(&self, f: i32, u: i32, v: i32) -> i32 {
        let x = u - i32::from(self.width) * 8;
        let y = v - i32::from(self.height) * 8;
        let (s, c) = sin_cos(from_mrad(i32::from(self.tilt_mrad)));
        // The ray times the focal length: forward f cos(t) - y sin(t), left -x.
        atan2(-x, mul_q14(f, c) - mul_q14(y, s))
    }

    /// Bearing and range of a blob that is a whole marker. Range comes from the marker's angular
    /// width: the edge rays are tangent to the cylinder, so `range = (d / 2) / sin(width / 2)`.
    /// Fixed point throughout (bearings within 0.1 mrad of the `f32` model's; the pixel edges
    /// limit both figures far more).
    pub fn observe(&self, blob: &Blob, marker: &MarkerModel) -> Observation {
        let area = blob.area.max(1);
        // The centroid's row, plus half a pixel (the pixel's centre), in 1/16 pixel.
        let v = (blob.sum_y / area) * 16 + (blob.sum_y % area) * 16 / area + 8;
        let v = v.min(i32::MAX as u32) as i32;
        let f = self.focal_q4();
        let left = self.bearing_q4(f, i32::from(blob.min_x) * 16, v);
        let right = self.bearing_q4(f, (i32::from(blob.max_x) + 1) * 16, v);
        let bearing = (left + right) / 2;
        // At least one binary angle (0.1 mrad) of half-width.
        let half = ((left - right) / 2).max(1);
        // d / 2 / sin(half), with the sine in Q14.
        let range = u32::from(marker.diameter_mm) * 8192 / sin_cos(half).0.max(1) as u32;
        Observation {
            class: blob.class,
            bearing_mrad: to_mrad(bearing),
            range_mm: range,
        }
    }

    /// Range from the image row of a point at a known height above the floor (for example the
    /// marker's centre); `None` when the ray does not come down (or up) to that height.
    pub fn range_from_row(&self, u: f32, v: f32, point_height_mm: f32) -> Option<f32> {
        let r = self.ray(u, v);
        let dz = point_height_mm - f32::from(self.height_mm);
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
        let half = (f32::from(mk.diameter_mm) * 0.5 / d).asin();
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

    /// `observe` in `f64`, the model's exact answer for a blob.
    fn observe_f64(m: &CameraModel, blob: &Blob, mk: &MarkerModel) -> (f64, f64) {
        let f = f64::from(m.width) / 2.0 / (f64::from(m.hfov_mrad) * 5e-4).tan();
        let t = f64::from(m.tilt_mrad) * 1e-3;
        let v = f64::from(blob.sum_y) / f64::from(blob.area.max(1)) + 0.5;
        let bearing = |u: f64| {
            let x = (u - f64::from(m.width) / 2.0) / f;
            let y = (v - f64::from(m.height) / 2.0) / f;
            (-x).atan2(t.cos() - y * t.sin())
        };
        let (l, r) = (
            bearing(f64::from(blob.min_x)),
            bearing(f64::from(blob.max_x) + 1.0),
        );
        let half = (0.5 * (l - r)).max(1e-4);
        (0.5 * (l + r), f64::from(mk.diameter_mm) * 0.5 / half.sin())
    }

    proptest::proptest! {
        /// The fixed-point observation against the exact model: bearing within 0.7 mrad (it is
        /// rounded to whole mrad), and
        /// the half-width angle the range stands for within 0.25 mrad (one pixel is 1.8 mrad).
        #[test]
        fn observe_matches_the_exact_model(
            min_x in 0u16..600,
            width in 4u16..200,
            row in 0u32..480,
            tilt in -200i16..200,
        ) {
            let m = CameraModel { tilt_mrad: tilt, ..CameraModel::default() };
            let mk = MarkerModel::default();
            let blob = Blob {
                class: 1,
                area: 10,
                sum_x: 0,
                sum_y: row * 10 + 3,
                min_x,
                max_x: (min_x + width).min(639),
                min_y: 0,
                max_y: 0,
            };
            let o = m.observe(&blob, &mk);
            let (bearing, range) = observe_f64(&m, &blob, &mk);
            proptest::prop_assert!((f64::from(o.bearing_mrad) - bearing * 1000.0).abs() <= 0.7, "{:?} {}", o, bearing);
            let d = f64::from(mk.diameter_mm) * 0.5;
            let half = (d / f64::from(o.range_mm)).min(1.0).asin();
            let exact = (d / range).min(1.0).asin();
            // The range is an integer in mm: half a mm of it in angle.
            let rounding = d / (range * range);
            proptest::prop_assert!((half - exact).abs() <= 0.25e-3 + rounding, "{:?} {} {} {}", o, range, half, exact);
        }
    }
}
