//! A group command from named arguments, as the command line (`key=value`) and the experiment
//! files give them: the law's parameters by name, the defaults of those not given, and the
//! option keys every law takes ([`OPTION_KEYS`]). Errors name the key and list what the law
//! accepts.

use core::fmt;

use crate::law::{Neighbours, Reverse, MAX_NEAREST};
use crate::param::{Param, MAX_PARAMS};
use crate::params::{ManeuverParams, Overrides};
use crate::registry::LawInfo;

/// Keys that set an option instead of a parameter (no law may name a parameter so).
pub const OPTION_KEYS: [&str; 3] = ["reverse", "arrival_units", "neighbours"];

/// Keys an experiment file's phase table uses itself (no law may name a parameter so).
pub const RESERVED_KEYS: [&str; 11] = [
    "kind",
    "start_s",
    "timeout_s",
    "hold_s",
    "tolerance_mm",
    "cars",
    "waypoints",
    "waypoint_at_s",
    "reach_units",
    "waypoint_cars",
    "id",
];

/// A value as written: a number or a word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arg<'a> {
    /// A number.
    Int(i64),
    /// A word (a choice's name, an option's mode).
    Word(&'a str),
}

impl<'a> Arg<'a> {
    /// `text` as a number when it is one, else as a word.
    pub fn parse(text: &'a str) -> Arg<'a> {
        text.parse().map_or(Arg::Word(text), Arg::Int)
    }
}

impl fmt::Display for Arg<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Arg::Int(v) => write!(f, "{v}"),
            Arg::Word(w) => write!(f, "{w:?}"),
        }
    }
}

/// Why arguments do not make a group command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArgError<'a> {
    /// Not `key=value`.
    NotKeyValue(&'a str),
    /// The law has no parameter of that name and it is no option key.
    Unknown {
        /// The law.
        law: &'static LawInfo,
        /// The key.
        key: &'a str,
    },
    /// The key is given twice.
    Duplicate(&'a str),
    /// Not one of [`OPTION_KEYS`].
    NotAnOption(&'a str),
    /// A parameter without a default is not given.
    Missing {
        /// The law.
        law: &'static LawInfo,
        /// The parameter.
        param: &'static Param,
    },
    /// The value is not one the key takes.
    BadValue {
        /// The key.
        key: &'a str,
        /// The value.
        value: Arg<'a>,
        /// What it takes.
        expected: Expected,
    },
}

/// What a key takes, for error messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expected {
    /// A number in this range.
    Range(i32, i32),
    /// One of these words (or its index).
    Choice(&'static [&'static str]),
    /// `allowed`, `turn` or `never`.
    Reverse,
    /// `all`, `none` or a count 1..=16.
    Neighbours,
}

impl fmt::Display for Expected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Expected::Range(a, b) => write!(f, "a number in {a}..={b}"),
            Expected::Choice(c) => {
                f.write_str("one of")?;
                for (i, w) in c.iter().enumerate() {
                    write!(f, "{}{w}", if i == 0 { " " } else { ", " })?;
                }
                Ok(())
            }
            Expected::Reverse => f.write_str("allowed, turn or never"),
            Expected::Neighbours => write!(f, "all, none or a count 1..={MAX_NEAREST}"),
        }
    }
}

/// Lists a law's parameters and the option keys.
struct Keys(&'static LawInfo);

impl fmt::Display for Keys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.params.is_empty() {
            f.write_str("it has no parameters")?;
        } else {
            f.write_str("its parameters are")?;
            for (i, p) in self.0.params.iter().enumerate() {
                write!(f, "{}{}", if i == 0 { " " } else { ", " }, p.name)?;
                if let Some(d) = p.default {
                    match p.choices.get(d as usize) {
                        Some(w) => write!(f, " (default {w})")?,
                        None => write!(f, " (default {d})")?,
                    }
                }
            }
        }
        f.write_str("; every law also takes reverse, arrival_units and neighbours")
    }
}

impl fmt::Display for ArgError<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ArgError::NotKeyValue(s) => write!(f, "{s:?} is not key=value"),
            ArgError::Unknown { law, key } => write!(
                f,
                "`{key}` is not a parameter of law `{}`: {}",
                law.name,
                Keys(law)
            ),
            ArgError::Duplicate(k) => write!(f, "`{k}` is given twice"),
            ArgError::NotAnOption(k) => write!(
                f,
                "`{k}` is not an option (the options are reverse, arrival_units, neighbours)"
            ),
            ArgError::Missing { law, param } => write!(
                f,
                "law `{}` needs `{}` ({}): {}",
                law.name,
                param.name,
                param.doc,
                Keys(law)
            ),
            ArgError::BadValue {
                key,
                value,
                expected,
            } => write!(f, "`{key}` = {value} is not {expected}"),
        }
    }
}

fn param_value<'a>(key: &'a str, p: &Param, value: Arg<'a>) -> Result<i32, ArgError<'a>> {
    let bad = || ArgError::BadValue {
        key,
        value,
        expected: if p.choices.is_empty() {
            Expected::Range(p.min, p.max)
        } else {
            Expected::Choice(p.choices)
        },
    };
    let v = match value {
        Arg::Int(v) => v,
        Arg::Word(w) => i64::from(p.choice_value(w).ok_or_else(bad)?),
    };
    if p.range().contains(v) {
        // In an i32 range.
        Ok(v as i32)
    } else {
        Err(bad())
    }
}

/// Sets option `key` (one of [`OPTION_KEYS`]) of `o` to `value`.
pub fn set_option<'a>(key: &'a str, value: Arg<'a>, o: &mut Overrides) -> Result<(), ArgError<'a>> {
    let bad = |expected| ArgError::BadValue {
        key,
        value,
        expected,
    };
    match key {
        "reverse" => {
            let Arg::Word(w) = value else {
                return Err(bad(Expected::Reverse));
            };
            o.reverse = Some(
                Reverse::ALL
                    .into_iter()
                    .find(|r| r.name() == w)
                    .ok_or(bad(Expected::Reverse))?,
            );
        }
        "arrival_units" => match value {
            Arg::Int(v @ 1..=255) => o.arrival_units = Some(v as u8),
            _ => return Err(bad(Expected::Range(1, 255))),
        },
        "neighbours" => {
            o.neighbours = Some(match value {
                Arg::Word("all") => Neighbours::All,
                Arg::Word("none") => Neighbours::None,
                Arg::Int(k) if (1..=i64::from(MAX_NEAREST)).contains(&k) => {
                    Neighbours::Nearest(k as u8)
                }
                _ => return Err(bad(Expected::Neighbours)),
            })
        }
        _ => return Err(ArgError::NotAnOption(key)),
    }
    Ok(())
}

impl LawInfo {
    /// The group command from named values (each key once); parameters not given take
    /// their defaults.
    pub fn build<'a>(
        &'static self,
        args: &[(&'a str, Arg<'a>)],
    ) -> Result<ManeuverParams, ArgError<'a>> {
        self.build_from(args.iter().map(|a| Ok(*a)))
    }

    /// The group command from `key=value` strings.
    pub fn parse<'a>(&'static self, args: &[&'a str]) -> Result<ManeuverParams, ArgError<'a>> {
        self.build_from(args.iter().map(|a| {
            a.split_once('=')
                .map(|(k, v)| (k, Arg::parse(v)))
                .ok_or(ArgError::NotKeyValue(a))
        }))
    }

    fn build_from<'a>(
        &'static self,
        args: impl IntoIterator<Item = Result<(&'a str, Arg<'a>), ArgError<'a>>>,
    ) -> Result<ManeuverParams, ArgError<'a>> {
        let mut values: [Option<i32>; MAX_PARAMS] = [None; MAX_PARAMS];
        let mut overrides = Overrides::default();
        let mut options_seen = [false; OPTION_KEYS.len()];
        for arg in args {
            let (key, value) = arg?;
            if let Some((i, p)) = self.param(key) {
                let slot = values
                    .get_mut(i)
                    .ok_or(ArgError::Unknown { law: self, key })?;
                if slot.is_some() {
                    return Err(ArgError::Duplicate(key));
                }
                *slot = Some(param_value(key, p, value)?);
            } else if let Some(k) = OPTION_KEYS.iter().position(|o| *o == key) {
                if options_seen[k] {
                    return Err(ArgError::Duplicate(key));
                }
                options_seen[k] = true;
                set_option(key, value, &mut overrides)?;
            } else {
                return Err(ArgError::Unknown { law: self, key });
            }
        }
        let mut out = [0i32; MAX_PARAMS];
        for (i, p) in self.params.iter().enumerate().take(MAX_PARAMS) {
            out[i] = values[i].or(p.default).ok_or(ArgError::Missing {
                law: self,
                param: p,
            })?;
        }
        let n = self.params.len().min(MAX_PARAMS);
        // Every value was checked against its range above, and a registry test checks every
        // law's defaults and parameter count, so this holds for every registered law.
        let params = ManeuverParams::new(self.id, &out[..n])
            .map_err(|_| ArgError::Unknown { law: self, key: "" })?;
        Ok(params.with_overrides(overrides))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registry::find;
    use crate::{Formation, GoTo, Shape};

    #[test]
    fn key_values_with_defaults_and_options() {
        let goto = find("goto").unwrap();
        let p = goto.parse(&["x=300", "y=600"]).unwrap();
        assert_eq!(p, GoTo::params(300, 600, 200).unwrap());
        let p = goto
            .parse(&[
                "y=600",
                "x=300",
                "speed_mm_s=250",
                "reverse=never",
                "arrival_units=20",
                "neighbours=3",
            ])
            .unwrap();
        assert_eq!(p.values().as_slice(), &[300, 600, 250]);
        let o = p.options().unwrap();
        assert_eq!(
            (o.reverse, o.arrival_units, o.neighbours),
            (Reverse::Never, 20, Neighbours::Nearest(3))
        );
        let f = find("formation").unwrap();
        assert_eq!(
            f.parse(&["leader=1", "shape=wedge", "slot=2"]).unwrap(),
            Formation::params(Shape::Wedge, 1, Some(2), 100, 150).unwrap()
        );
    }

    #[test]
    fn errors_name_the_key_and_list_the_parameters() {
        let goto = find("goto").unwrap();
        let e = goto.parse(&["x=300", "y=600", "sped=3"]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "`sped` is not a parameter of law `goto`: its parameters are x, y, speed_mm_s \
             (default 200); every law also takes reverse, arrival_units and neighbours"
        );
        let e = goto.parse(&["x=300"]).unwrap_err();
        assert!(e.to_string().starts_with("law `goto` needs `y`"), "{e}");
        assert_eq!(
            goto.parse(&["x=3000", "y=1"]).unwrap_err().to_string(),
            "`x` = 3000 is not a number in 0..=1023"
        );
        assert_eq!(
            goto.parse(&["x=1", "x=2", "y=1"]).unwrap_err(),
            ArgError::Duplicate("x")
        );
        assert_eq!(goto.parse(&["x"]).unwrap_err(), ArgError::NotKeyValue("x"));
        assert_eq!(
            goto.parse(&["x=1", "y=1", "reverse=sometimes"])
                .unwrap_err()
                .to_string(),
            "`reverse` = \"sometimes\" is not allowed, turn or never"
        );
        assert_eq!(
            find("formation")
                .unwrap()
                .parse(&["leader=1", "shape=v"])
                .unwrap_err()
                .to_string(),
            "`shape` = \"v\" is not one of line, wedge"
        );
    }
}
