//! Follow the car carrying a marker seen by the camera. The firmware's camera part steers the
//! car towards the marker its vision finds; this law only holds and reports, so the
//! controller sends nothing of its own ([`Law::DRIVES`] is false).

use crate::law::{Law, LawInput, Plan};
use crate::param::{Param, Values};
use crate::Phase;

/// The camera-follow law's parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraFollow {
    /// Vision colour class of the leader's marker.
    pub marker: u8,
    /// Distance to keep behind the leader, tracking units.
    pub distance_units: u16,
    /// Maximum speed, mm/s.
    pub speed_mm_s: u16,
}

impl Law for CameraFollow {
    const NAME: &'static str = "camera-follow";
    const SUMMARY: &'static str = "Follow the car carrying a marker seen by the on-board camera (carried out by the firmware's camera part; needs camera frames).";
    const PARAMS: &'static [Param] = &[
        Param::int("marker", "", 0, 255).doc("vision colour class of the leader's marker"),
        Param::int("distance_units", "units", 1, 511)
            .default(80)
            .doc("distance to keep behind the leader"),
        Param::int("speed_mm_s", "mm/s", 0, 2047)
            .default(150)
            .doc("maximum speed"),
    ];
    const DRIVES: bool = false;
    const CONVERGES: bool = false;

    fn new(p: &Values) -> Self {
        CameraFollow {
            marker: p.u8(0),
            distance_units: p.u16(1),
            speed_mm_s: p.u16(2),
        }
    }

    fn step(&mut self, _input: &LawInput<'_>) -> Plan {
        Plan::hold(Phase::Hold, false, 0)
    }
}

impl CameraFollow {
    /// The group command for a camera follow.
    pub fn params(
        marker: u8,
        distance_units: u16,
        speed_mm_s: u16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[
                i32::from(marker),
                i32::from(distance_units),
                i32::from(speed_mm_s),
            ],
        )
    }
}
