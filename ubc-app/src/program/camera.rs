//! The camera side of the program: the latest detections of the on-board vision (the board
//! layer grabs each new frame and runs `vision::process_frame` on it), the console's `Camera`
//! report, and the camera-follow maneuver's [`Follower`](vision::follow::Follower).
//!
//! Console tag 0x09 `Camera`: the request body is one byte, the index of the blob to include
//! (blobs are largest first); the reply body (30 bytes at most, little-endian) is
//!
//! | bytes | field |
//! |---|---|
//! | 4 | frame sequence of the detections (0: no frame yet) |
//! | 1 | blobs in that frame |
//! | 1 | marker class followed (0: no camera-follow maneuver) |
//! | 1 | follow state (`FollowState::code`; 0xFF: none) |
//! | 2 | leader bearing, mrad (i16, positive left) |
//! | 2 | leader range, mm (0: not in this frame) |
//! | 2 | frames processed since boot, modulo 65536 (a reader also takes the 11-byte report without it: 0) |
//! | 1 | index of the blob below (absent with the blob when the index is past the last) |
//! | 1 | blob class |
//! | 3 | blob area, pixels (saturating) |
//! | 2+2 | blob centroid column and row, quarter pixels |
//! | 2+2+2+2 | bounding box min x, min y, max x, max y (inclusive) |

use super::group::{Gated, SendGate, STEER_STEP_MRAD, VELOCITY_STEP_MM_S};
use vision::blobs::{Blob, Detections};
use vision::follow::{observe_class, FollowCommand, FollowConfig, FollowTarget, Follower};
use vision::pinhole::{CameraModel, MarkerModel, Observation};

/// Millimetres per tracking unit.
const MM_PER_UNIT_X2: u32 = 5;

/// Bytes of the report without a blob.
pub const REPORT_LEN: usize = 13;
/// Bytes of the report without a blob and without the frame count (still read).
pub const REPORT_LEN_V1: usize = 11;
/// Bytes of one blob in the report (with its index).
pub const BLOB_LEN: usize = 17;

/// One blob as reported to the console.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BlobReport {
    pub class: u8,
    /// Pixels, saturating at `0xFF_FFFF`.
    pub area: u32,
    /// Centroid column, quarter pixels.
    pub cx_q2: u16,
    /// Centroid row, quarter pixels.
    pub cy_q2: u16,
    pub min_x: u16,
    pub min_y: u16,
    pub max_x: u16,
    pub max_y: u16,
}

impl From<&Blob> for BlobReport {
    fn from(b: &Blob) -> Self {
        let (cx, cy) = b.centroid_q8();
        let q2 = |v: u32| u16::try_from((v + 32) >> 6).unwrap_or(u16::MAX);
        BlobReport {
            class: b.class,
            area: b.area.min(0xFF_FFFF),
            cx_q2: q2(cx),
            cy_q2: q2(cy),
            min_x: b.min_x,
            min_y: b.min_y,
            max_x: b.max_x,
            max_y: b.max_y,
        }
    }
}

/// The console's camera report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CameraReport {
    /// Frame sequence of the detections (0: none yet).
    pub sequence: u32,
    /// Blobs found in that frame.
    pub blobs: u8,
    /// Marker class followed (0: no camera-follow maneuver).
    pub leader_class: u8,
    /// `FollowState::code`, 0xFF without a camera-follow maneuver.
    pub follow_state: u8,
    /// Bearing of the leader's marker, mrad, positive left.
    pub leader_bearing_mrad: i16,
    /// Range of the leader's marker, mm; 0 when it is not in the frame.
    pub leader_range_mm: u16,
    /// Frames the vision pipeline processed since boot, modulo 65536.
    pub frames: u16,
    /// The blob asked for, with its index.
    pub blob: Option<(u8, BlobReport)>,
}

/// Why a report does not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReportError {
    /// The body is neither [`REPORT_LEN`] nor `REPORT_LEN + BLOB_LEN` bytes.
    Length { got: usize },
    /// The output buffer is too small.
    BufferTooSmall { needed: usize },
}

impl CameraReport {
    /// Writes the reply body; returns its length.
    pub fn write(&self, out: &mut [u8]) -> Result<usize, ReportError> {
        let len = REPORT_LEN + if self.blob.is_some() { BLOB_LEN } else { 0 };
        let out = out
            .get_mut(..len)
            .ok_or(ReportError::BufferTooSmall { needed: len })?;
        out[0..4].copy_from_slice(&self.sequence.to_le_bytes());
        out[4] = self.blobs;
        out[5] = self.leader_class;
        out[6] = self.follow_state;
        out[7..9].copy_from_slice(&self.leader_bearing_mrad.to_le_bytes());
        out[9..11].copy_from_slice(&self.leader_range_mm.to_le_bytes());
        out[11..13].copy_from_slice(&self.frames.to_le_bytes());
        if let Some((i, b)) = self.blob {
            let o = &mut out[REPORT_LEN..];
            o[0] = i;
            o[1] = b.class;
            o[2..5].copy_from_slice(&b.area.min(0xFF_FFFF).to_le_bytes()[..3]);
            for (k, v) in [b.cx_q2, b.cy_q2, b.min_x, b.min_y, b.max_x, b.max_y]
                .iter()
                .enumerate()
            {
                o[5 + 2 * k..7 + 2 * k].copy_from_slice(&v.to_le_bytes());
            }
        }
        Ok(len)
    }

    /// Reads a reply body.
    pub fn read(b: &[u8]) -> Result<Self, ReportError> {
        let base = match b.len() {
            n if n == REPORT_LEN || n == REPORT_LEN + BLOB_LEN => REPORT_LEN,
            n if n == REPORT_LEN_V1 || n == REPORT_LEN_V1 + BLOB_LEN => REPORT_LEN_V1,
            got => return Err(ReportError::Length { got }),
        };
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let blob = (b.len() > base).then(|| {
            let o = base;
            (
                b[o],
                BlobReport {
                    class: b[o + 1],
                    area: u32::from_le_bytes([b[o + 2], b[o + 3], b[o + 4], 0]),
                    cx_q2: u16_at(o + 5),
                    cy_q2: u16_at(o + 7),
                    min_x: u16_at(o + 9),
                    min_y: u16_at(o + 11),
                    max_x: u16_at(o + 13),
                    max_y: u16_at(o + 15),
                },
            )
        });
        Ok(CameraReport {
            sequence: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            blobs: b[4],
            leader_class: b[5],
            follow_state: b[6],
            leader_bearing_mrad: i16::from_le_bytes([b[7], b[8]]),
            leader_range_mm: u16_at(9),
            frames: if base == REPORT_LEN { u16_at(11) } else { 0 },
            blob,
        })
    }
}

/// Camera state of the program.
#[derive(Debug, Clone, Default)]
pub struct Camera {
    model: CameraModel,
    marker: MarkerModel,
    sequence: u32,
    frames: u16,
    detections: Detections,
    follower: Option<Follower>,
    leader: Option<Observation>,
    /// Which follow commands go to the LBC.
    gate: SendGate<FollowCommand>,
}

/// The group maneuvers' thresholds; a zero velocity is the stop.
impl Gated for FollowCommand {
    fn is_stop(&self) -> bool {
        self.velocity_mm_s == 0
    }

    fn differs_from(&self, last: &Self) -> bool {
        (self.steering_mrad - last.steering_mrad).abs() >= STEER_STEP_MRAD
            || (self.velocity_mm_s - last.velocity_mm_s).abs() >= VELOCITY_STEP_MM_S
            || self.is_stop() != last.is_stop()
    }
}

impl Camera {
    /// Starts following the marker of class `marker` at `distance_units` (tracking units) and up
    /// to `speed_mm_s`.
    pub fn start_follow(&mut self, marker: u8, distance_units: u16, speed_mm_s: u16) {
        let target = FollowTarget {
            class: marker,
            distance_mm: u32::from(distance_units) * MM_PER_UNIT_X2 / 2,
            max_speed_mm_s: speed_mm_s,
        };
        if self.follower.map(|f| *f.target()) != Some(target) {
            self.follower = Some(Follower::new(target, FollowConfig::default()));
            self.leader = None;
            self.gate.reset();
        }
    }

    /// Ends the camera-follow maneuver.
    pub fn stop_follow(&mut self) {
        self.follower = None;
        self.leader = None;
        self.gate.reset();
    }

    /// True while following.
    #[must_use]
    pub fn following(&self) -> bool {
        self.follower.is_some()
    }

    /// The detections of frame `sequence`, processed at `now_us`.
    pub fn on_frame(&mut self, now_us: u64, sequence: u32, detections: &Detections) {
        self.sequence = sequence;
        self.frames = self.frames.wrapping_add(1);
        self.detections = *detections;
        if let Some(f) = self.follower.as_mut() {
            let class = f.target().class;
            self.leader = observe_class(detections, class, &self.model, &self.marker);
            f.on_frame(now_us, self.leader);
        }
    }

    /// The follow command for now, while following.
    pub fn follow_command(&mut self, now_us: u64) -> Option<FollowCommand> {
        self.follower.as_mut().map(|f| f.command(now_us))
    }

    /// One control period while following: the command to send to the LBC now, if any. Like
    /// the group maneuvers, a command goes out when it changes meaningfully (at most every
    /// `MIN_INTERVAL_US`), a stop at once, and an unchanged one again every `REFRESH_US`.
    /// `may_send` is false while an earlier command is still with the LBC client.
    pub fn step(&mut self, now_us: u64, may_send: bool) -> Option<FollowCommand> {
        let next = self.follow_command(now_us)?;
        self.gate.offer(now_us, next, may_send)
    }

    /// The last command handed out did not reach the LBC: send again at the next period.
    pub fn unsent(&mut self) {
        self.gate.reset();
    }

    /// Sequence of the latest processed frame (0: none).
    #[must_use]
    pub fn sequence(&self) -> u32 {
        self.sequence
    }

    /// The latest detections.
    #[must_use]
    pub fn detections(&self) -> &Detections {
        &self.detections
    }

    /// The console report with blob `index` (largest first) if there is one.
    #[must_use]
    pub fn report(&self, index: u8) -> CameraReport {
        let blobs = self.detections.blobs();
        let (leader_class, follow_state) = self
            .follower
            .as_ref()
            .map_or((0, 0xFF), |f| (f.target().class, f.state().code()));
        let (bearing, range) = self.leader.map_or((0, 0), |o| {
            (
                o.bearing_mrad
                    .clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16,
                u16::try_from(o.range_mm).unwrap_or(u16::MAX),
            )
        });
        CameraReport {
            sequence: self.sequence,
            blobs: u8::try_from(blobs.len()).unwrap_or(u8::MAX),
            leader_class,
            follow_state,
            leader_bearing_mrad: bearing,
            leader_range_mm: range,
            frames: self.frames,
            blob: blobs
                .get(usize::from(index))
                .map(|b| (index, BlobReport::from(b))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::group::REFRESH_US;
    use proptest::prelude::*;
    use vision::blobs::{BlobDetector, Run};

    fn detections() -> Detections {
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        for y in 200..230 {
            d.push_row(
                y,
                &[
                    Run {
                        start: 300,
                        end: 340,
                        class: 2,
                    },
                    Run {
                        start: 500,
                        end: 505,
                        class: 3,
                    },
                ],
            );
        }
        d.finish(4)
    }

    #[test]
    fn report_bytes_are_exact() {
        let mut cam = Camera::default();
        assert_eq!(
            cam.report(0),
            CameraReport {
                follow_state: 0xFF,
                ..CameraReport::default()
            }
        );
        cam.start_follow(2, 200, 300);
        cam.on_frame(1000, 7, &detections());
        let r = cam.report(1);
        let mut out = [0u8; 34];
        let n = r.write(&mut out).unwrap();
        assert_eq!(n, 30);
        let range = r.leader_range_mm.to_le_bytes();
        let expected = [
            7, 0, 0, 0, // sequence
            2, // blobs
            2, // class followed
            1, // tracking
            0, 0, // bearing: straight ahead
            range[0], range[1], // range, checked below
            1, 0, // frames processed
            1, // blob index
            3, // class
            150, 0, 0, // area 5 x 30
            0xD8, 0x07, // cx 502.0 * 4 = 2008
            0x5A, 0x03, // cy 214.5 * 4 = 858
            0xF4, 0x01, 200, 0, 0xF8, 0x01, 229, 0, // box 500,200 - 504,229
        ];
        assert_eq!(out[..n], expected);
        assert_eq!(CameraReport::read(&out[..n]), Ok(r));
        // The marker spans columns 300..340, centred on the image: straight ahead.
        assert_eq!(r.leader_bearing_mrad, 0);
        assert!((500..700).contains(&r.leader_range_mm), "{r:?}");
        assert_eq!(cam.report(2).blob, None);
        assert_eq!(
            CameraReport::read(&out[..12]),
            Err(ReportError::Length { got: 12 })
        );
        assert_eq!(
            r.write(&mut [0u8; 20]),
            Err(ReportError::BufferTooSmall { needed: 30 })
        );
    }

    #[test]
    fn follow_commands_come_from_the_marker() {
        let mut cam = Camera::default();
        assert_eq!(cam.follow_command(0), None);
        // 200 units = 500 mm; the marker is further, so the car drives.
        cam.start_follow(2, 200, 300);
        cam.on_frame(1000, 1, &detections());
        let c = cam.follow_command(2000).unwrap();
        assert!(c.velocity_mm_s > 0, "{c:?}");
        cam.stop_follow();
        assert!(!cam.following());
        assert_eq!(cam.report(0).follow_state, 0xFF);
    }

    #[test]
    fn commands_are_gated_like_group_commands() {
        let mut cam = Camera::default();
        assert_eq!(cam.step(0, true), None);
        cam.start_follow(2, 200, 300);
        cam.on_frame(0, 1, &detections());
        let first = cam.step(0, true).unwrap();
        assert!(first.velocity_mm_s > 0);
        // Unchanged (the same frame keeps coming): nothing until the refresh, and not while
        // the client is busy.
        cam.on_frame(150_000, 2, &detections());
        assert_eq!(cam.step(150_000, true), None);
        cam.on_frame(REFRESH_US, 3, &detections());
        assert_eq!(cam.step(REFRESH_US, false), None);
        assert_eq!(cam.step(REFRESH_US, true), Some(first));
        cam.unsent();
        assert_eq!(cam.step(REFRESH_US + 1, true), Some(first));
        // Restarting with the same target keeps the state.
        cam.start_follow(2, 200, 300);
        assert!(cam.following());
        assert_eq!(cam.step(REFRESH_US + 2, true), None);
        // The marker is lost: the ramp down changes the command, and the stop goes out at once.
        let later = REFRESH_US + 300_000 + 800_000;
        let slower = cam.step(later, true).unwrap();
        assert!(slower.velocity_mm_s < first.velocity_mm_s, "{slower:?}");
        assert_eq!(
            cam.step(later + 1_000_000, true),
            Some(FollowCommand::default())
        );
    }

    proptest! {
        #[test]
        fn report_round_trips(
            seq in any::<u32>(), blobs in any::<u8>(), class in any::<u8>(), state in any::<u8>(),
            bearing in any::<i16>(), range in any::<u16>(), with_blob in any::<bool>(),
            idx in any::<u8>(), area in 0u32..=0xFF_FFFF, f in any::<[u16; 6]>(),
        ) {
            let r = CameraReport {
                sequence: seq, blobs, leader_class: class, follow_state: state,
                leader_bearing_mrad: bearing, leader_range_mm: range, frames: seq as u16 ^ 0x5555,
                blob: with_blob.then_some((idx, BlobReport {
                    class, area, cx_q2: f[0], cy_q2: f[1], min_x: f[2], min_y: f[3],
                    max_x: f[4], max_y: f[5],
                })),
            };
            let mut out = [0u8; 32];
            let n = r.write(&mut out).unwrap();
            prop_assert_eq!(CameraReport::read(&out[..n]), Ok(r));
            // The report of firmware without the frame count still reads, frames = 0.
            let mut old = [0u8; 28];
            old[..REPORT_LEN_V1].copy_from_slice(&out[..REPORT_LEN_V1]);
            let rest = n - REPORT_LEN;
            old[REPORT_LEN_V1..REPORT_LEN_V1 + rest].copy_from_slice(&out[REPORT_LEN..n]);
            let back = CameraReport::read(&old[..REPORT_LEN_V1 + rest]).unwrap();
            prop_assert_eq!(back, CameraReport { frames: 0, ..r });
        }

        #[test]
        fn read_never_panics(b in proptest::collection::vec(any::<u8>(), 0..40)) {
            let _ = CameraReport::read(&b);
        }
    }
}
