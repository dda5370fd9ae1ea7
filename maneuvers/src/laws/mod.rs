//! The registration list: every group-maneuver law and its wire ID, one line each.
//!
//! The firmware, the controller, `almc` and the experiment files all read this list. To add a
//! law, write it in its own file in this directory (a type implementing
//! [`crate::law::Law`]) and add its line here: `ID => file_name::TypeName,`. IDs 1..=15 are
//! the project's own laws; give yours an unused ID from 16 to 255 and never reuse one (it is
//! what group commands carry). `docs/writing-a-law.md` walks through an example.

crate::registry::register_laws! {
    1 => formation::Formation,
    2 => rendezvous::Rendezvous,
    3 => circle::Circle,
    4 => goto::GoTo,
    5 => camera_follow::CameraFollow,
    16 => platoon::Platoon,
}
