//! `almc laws`: the registered group-maneuver laws (from `maneuvers::laws`, the list the
//! firmware is built with), and the parsing of `group start LAW key=value ...`.

use std::process::ExitCode;

use clap::Args;
use maneuvers::args::OPTION_KEYS;
use maneuvers::reference::{write_law, write_markdown};
use maneuvers::{registry, LawInfo, ManeuverParams, LAWS};
use serde_json::{json, Value};

/// `almc laws ...`
#[derive(Debug, Args)]
pub struct LawsArgs {
    /// Only this law.
    law: Option<String>,
    /// Print JSON instead of the markdown reference.
    #[arg(long)]
    json: bool,
}

/// "unknown law" with the registered names.
pub fn unknown_law(name: &str) -> String {
    let names: Vec<&str> = LAWS.iter().map(|l| l.name).collect();
    format!(
        "unknown law `{name}`; the registered laws are {} (`almc laws` describes them)",
        names.join(", ")
    )
}

/// The law called `name`.
pub fn find(name: &str) -> Result<&'static LawInfo, String> {
    registry::find(name).ok_or_else(|| unknown_law(name))
}

/// The group command for `law` with `key=value` arguments (checked against the law's
/// parameters; an error says what it takes).
pub fn group_params(law: &str, args: &[String]) -> Result<ManeuverParams, String> {
    let info = find(law)?;
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    info.parse(&args).map_err(|e| e.to_string())
}

/// One law as JSON.
pub fn law_json(l: &LawInfo) -> Value {
    json!({
        "id": l.id,
        "name": l.name,
        "summary": l.summary,
        "drives": l.drives,
        "params": l.params.iter().map(|p| json!({
            "name": p.name,
            "unit": p.unit,
            "min": p.min,
            "max": p.max,
            "default": p.default,
            "choices": p.choices,
            "doc": p.doc,
        })).collect::<Vec<_>>(),
        "options": {
            "reverse": l.options.reverse.name(),
            "arrival_units": l.options.arrival_units,
            "neighbours": match l.options.neighbours {
                maneuvers::Neighbours::All => json!("all"),
                maneuvers::Neighbours::None => json!("none"),
                maneuvers::Neighbours::Nearest(k) => json!(k),
            },
        },
        "option_keys": OPTION_KEYS,
        "wire_bytes": l.wire_len(),
    })
}

/// Runs `almc laws`.
pub fn run(args: &LawsArgs) -> ExitCode {
    let chosen: Vec<&LawInfo> = match &args.law {
        None => LAWS.iter().collect(),
        Some(name) => match find(name) {
            Ok(l) => vec![l],
            Err(e) => {
                eprintln!("almc laws: {e}");
                return ExitCode::from(2);
            }
        },
    };
    if args.json {
        println!(
            "{}",
            Value::Array(chosen.into_iter().map(law_json).collect())
        );
        return ExitCode::SUCCESS;
    }
    let mut text = String::new();
    let written = if args.law.is_none() {
        write_markdown(&mut text)
    } else {
        chosen.iter().try_for_each(|l| write_law(&mut text, l))
    };
    if written.is_err() {
        return ExitCode::FAILURE;
    }
    print!("{text}");
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laws_by_name_with_key_values() {
        assert_eq!(
            group_params("goto", &["x=300".into(), "y=600".into()]).unwrap(),
            maneuvers::GoTo::params(300, 600, 200).unwrap()
        );
        let e = group_params("gotoo", &[]).unwrap_err();
        assert!(
            e.starts_with("unknown law `gotoo`; the registered laws are formation, rendezvous"),
            "{e}"
        );
        let e = group_params("rendezvous", &["radius=3".into()]).unwrap_err();
        assert!(e.contains("its parameters are radius_units"), "{e}");
        let v = law_json(find("circle").unwrap());
        assert_eq!(v["params"][3]["name"], "speed_mm_s");
        assert_eq!(v["options"]["reverse"], "allowed");
    }
}
