//! What the registration list (`laws/mod.rs`) generates, and the look-ups on it.
//!
//! [`register_laws!`] turns the list `ID => module::Type,` into: the law modules, the table
//! [`LawInfo`] of every law (`laws::LAWS`: names, parameters, options; for the command line,
//! the experiment files and the docs), the enum `laws::AnyLaw` the controller runs (no heap,
//! no dynamic dispatch), and the parameter ranges by ID (`laws::ranges`, compile-time
//! constants without any text, which is all the firmware needs to check a group command).

use core::marker::PhantomData;

use crate::law::{Law, LawOptions};
use crate::laws::LAWS;
use crate::param::Param;

/// A registered law's wire ID (implemented by the registration list).
pub trait Registered: Law {
    /// The law's ID in group commands and status reports.
    const ID: u8;
}

/// One registered law, as tools and docs see it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LawInfo {
    /// Wire ID.
    pub id: u8,
    /// Name in commands and files.
    pub name: &'static str,
    /// What it does.
    pub summary: &'static str,
    /// Its parameters in wire order.
    pub params: &'static [Param],
    /// Its default options.
    pub options: LawOptions,
    /// Whether the controller's commands drive the car.
    pub drives: bool,
    /// Whether the law can report convergence ([`Law::CONVERGES`]).
    pub converges: bool,
}

impl LawInfo {
    /// The entry of law `L` with ID `id`.
    pub const fn of<L: Law>(id: u8) -> LawInfo {
        LawInfo {
            id,
            name: L::NAME,
            summary: L::SUMMARY,
            params: L::PARAMS,
            options: L::OPTIONS,
            drives: L::DRIVES,
            converges: L::CONVERGES,
        }
    }

    /// The parameter called `name` and its index.
    pub fn param(&self, name: &str) -> Option<(usize, &'static Param)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }

    /// Bytes of the law's group command body (header and parameters).
    pub fn wire_len(&self) -> usize {
        crate::params::HEADER_LEN + self.params.iter().map(Param::wire_len).sum::<usize>()
    }
}

/// The law called `name`.
pub fn find(name: &str) -> Option<&'static LawInfo> {
    LAWS.iter().find(|l| l.name == name)
}

/// The law with ID `id`.
pub fn by_id(id: u8) -> Option<&'static LawInfo> {
    LAWS.iter().find(|l| l.id == id)
}

/// The name of law `id` for reports: `none` for 0, `law <id>` for an unknown one.
pub fn name_of(id: u8) -> LawName {
    LawName(id)
}

/// Display of a law ID by name.
#[derive(Debug, Clone, Copy)]
pub struct LawName(u8);

impl core::fmt::Display for LawName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match (self.0, by_id(self.0)) {
            (0, _) => f.write_str("none"),
            (_, Some(l)) => f.write_str(l.name),
            (id, None) => write!(f, "law {id}"),
        }
    }
}

/// Compile-time facts of law `L` for the generated tables.
#[derive(Debug)]
pub struct Wire<L>(PhantomData<L>);

impl<L: Law> Wire<L> {
    /// Number of parameters.
    pub const LEN: usize = L::PARAMS.len();
}

/// Generates the registry from the list `ID => module::Type,` (see the module docs).
macro_rules! register_laws {
    ($($id:literal => $module:ident :: $law:ident,)+) => {
        $(pub mod $module;)+
        $(pub use $module::$law;)+

        $(impl $crate::registry::Registered for $law {
            const ID: u8 = $id;
        })+

        /// Every registered law, in the order of the list.
        pub const LAWS: &[$crate::registry::LawInfo] =
            &[$($crate::registry::LawInfo::of::<$law>($id),)+];

        /// A running law of any registered kind.
        #[derive(Debug, Clone)]
        #[allow(clippy::large_enum_variant)]
        pub enum AnyLaw {
            $(
                #[doc = concat!("The `", stringify!($module), "` law.")]
                $law($law),
            )+
        }

        impl AnyLaw {
            /// Law `law` built from its parameter values (`None`: not registered).
            pub fn new(law: u8, values: &$crate::param::Values) -> Option<AnyLaw> {
                match law {
                    $($id => Some(AnyLaw::$law(<$law as $crate::law::Law>::new(values))),)+
                    _ => None,
                }
            }

            /// The law's ID.
            pub fn id(&self) -> u8 {
                match self {
                    $(AnyLaw::$law(_) => $id,)+
                }
            }

            /// One control period of the law.
            pub fn step(&mut self, input: &$crate::law::LawInput<'_>) -> $crate::law::Plan {
                match self {
                    $(AnyLaw::$law(l) => $crate::law::Law::step(l, input),)+
                }
            }

            /// Whether car `id` leads the group.
            pub fn leads(&self, id: u8) -> bool {
                match self {
                    $(AnyLaw::$law(l) => $crate::law::Law::leads(l, id),)+
                }
            }

            /// Whether the controller's commands drive the car.
            pub fn drives(&self) -> bool {
                match self {
                    $(AnyLaw::$law(_) => <$law as $crate::law::Law>::DRIVES,)+
                }
            }
        }

        /// Every law's parameter ranges, one after the other in the order of the list: a
        /// compile-time table without names or texts (what the firmware keeps).
        const ALL_RANGES: [$crate::param::Range; 0 $(+ $crate::registry::Wire::<$law>::LEN)+] = {
            let mut out = [$crate::param::Range { min: 0, max: 0 };
                0 $(+ $crate::registry::Wire::<$law>::LEN)+];
            let mut k = 0;
            $(
                let p = <$law as $crate::law::Law>::PARAMS;
                let mut i = 0;
                while i < p.len() {
                    out[k] = p[i].range();
                    k += 1;
                    i += 1;
                }
            )+
            out
        };

        /// Parameter ranges of law `law` (`None`: not registered).
        pub fn ranges(law: u8) -> Option<&'static [$crate::param::Range]> {
            let mut start = 0;
            $(
                let end = start + $crate::registry::Wire::<$law>::LEN;
                if law == $id {
                    return ALL_RANGES.get(start..end);
                }
                start = end;
            )+
            let _ = start;
            None
        }

        /// Default options of law `law` (`None`: not registered).
        pub fn default_options(law: u8) -> Option<$crate::law::LawOptions> {
            match law {
                $($id => Some(<$law as $crate::law::Law>::OPTIONS),)+
                _ => None,
            }
        }
    };
}
pub(crate) use register_laws;

#[cfg(test)]
mod tests {
    //! Checks every registered law (a law added to the list is checked with the rest).

    use super::*;
    use crate::args::{OPTION_KEYS, RESERVED_KEYS};
    use crate::law::{GoalArea, LawInput, Waypoint};
    use crate::laws::AnyLaw;
    use crate::param::Values;
    use crate::params::{ManeuverParams, MAX_LEN};
    use crate::{CarPose, Neighbour};

    fn name_ok(name: &str, extra: u8) -> bool {
        !name.is_empty()
            && name.len() <= 24
            && name.as_bytes()[0].is_ascii_lowercase()
            && name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == extra)
    }

    #[test]
    fn the_list_is_consistent() {
        for (i, law) in LAWS.iter().enumerate() {
            assert!(law.id != 0, "{}: ID 0 means no maneuver", law.name);
            assert!(name_ok(law.name, b'-'), "law name {:?}", law.name);
            assert!(!law.summary.is_empty(), "{}: no summary", law.name);
            for other in &LAWS[i + 1..] {
                assert!(other.id != law.id, "ID {} twice", law.id);
                assert!(other.name != law.name, "name {} twice", law.name);
            }
            assert!(
                law.params.len() <= crate::param::MAX_PARAMS,
                "{}: too many",
                law.name
            );
            assert!(
                law.wire_len() <= MAX_LEN,
                "{}: {} bytes",
                law.name,
                law.wire_len()
            );
            let o = law.options;
            assert!(o.arrival_units > 0, "{}", law.name);
            for (k, p) in law.params.iter().enumerate() {
                let at = format!("{}.{}", law.name, p.name);
                assert!(name_ok(p.name, b'_'), "{at}: parameter name");
                assert!(!p.doc.is_empty(), "{at}: no doc");
                assert!(p.min <= p.max, "{at}: empty range");
                assert!(
                    !OPTION_KEYS.contains(&p.name) && !RESERVED_KEYS.contains(&p.name),
                    "{at}: the name is reserved"
                );
                if let Some(d) = p.default {
                    assert!(p.range().contains(d.into()), "{at}: default out of range");
                }
                if !p.choices.is_empty() {
                    assert_eq!((p.min, p.max as usize), (0, p.choices.len() - 1), "{at}");
                }
                assert!(
                    law.params[k + 1..].iter().all(|q| q.name != p.name),
                    "{at} twice"
                );
            }
            assert_eq!(find(law.name), Some(law));
            assert_eq!(by_id(law.id), Some(law));
            let r = crate::laws::ranges(law.id).unwrap();
            assert_eq!(r.len(), law.params.len());
            assert!(law.params.iter().zip(r).all(|(p, r)| p.range() == *r));
            assert_eq!(crate::laws::default_options(law.id), Some(law.options));
        }
    }

    /// Every law runs from its smallest, largest and default values, with and without
    /// neighbours and waypoints, without panicking.
    #[test]
    fn every_law_steps_over_its_ranges() {
        let area = GoalArea {
            x_min: 58,
            x_max: 542,
            y_min: 58,
            y_max: 742,
        };
        let others: Vec<Neighbour> = (2..6)
            .map(|id| Neighbour {
                id,
                pose: CarPose {
                    x: 100 * u16::from(id),
                    y: 300 + 20 * u16::from(id),
                    heading_mrad: 1000 * u16::from(id),
                    velocity_mm_s: 100,
                },
                age_us: 40_000,
            })
            .collect();
        for law in LAWS {
            let pick = |f: fn(&Param) -> i32| -> Vec<i32> { law.params.iter().map(f).collect() };
            for values in [
                pick(|p| p.min),
                pick(|p| p.max),
                pick(|p| p.default.unwrap_or(p.min)),
            ] {
                let v = Values::from_slice(&values).unwrap();
                let mut l = AnyLaw::new(law.id, &v).unwrap();
                assert_eq!(l.id(), law.id);
                assert_eq!(l.drives(), law.drives);
                assert!(ManeuverParams::new(law.id, &values).is_ok(), "{}", law.name);
                for id in [1u8, 3, 126] {
                    for (k, neighbours) in [&others[..], &[]].into_iter().enumerate() {
                        let plan = l.step(&LawInput {
                            now_us: 1_000_000 * u64::from(id),
                            id,
                            own: CarPose {
                                x: 300,
                                y: 400,
                                heading_mrad: 3000,
                                velocity_mm_s: -50,
                            },
                            neighbours,
                            waypoint: (k == 0).then_some(Waypoint {
                                x: 200,
                                y: 700,
                                index: 0,
                            }),
                            options: law.options,
                            area,
                        });
                        assert!(plan.phase.bits() <= 5, "{}", law.name);
                    }
                }
            }
        }
    }

    #[test]
    fn names_of_ids() {
        assert_eq!(name_of(0).to_string(), "none");
        assert_eq!(name_of(4).to_string(), "goto");
        assert_eq!(name_of(250).to_string(), "law 250");
    }
}
