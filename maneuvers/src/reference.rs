//! The reference of every registered law as markdown: name, ID, what it does, its parameters
//! and its default options. `docs/maneuvers.md` holds this text between two markers (the
//! test `maneuvers/tests/laws_doc.rs` keeps it current) and `almc laws` prints it.

use core::fmt::{self, Write};

use crate::law::{LawOptions, Neighbours};
use crate::laws::LAWS;
use crate::param::Param;
use crate::registry::LawInfo;

/// Line before the generated text in `docs/maneuvers.md`.
pub const BEGIN_MARKER: &str = "<!-- laws reference: generated from the registration list -->";
/// Line after it.
pub const END_MARKER: &str = "<!-- end of the laws reference -->";

struct Neigh(Neighbours);

impl fmt::Display for Neigh {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Neighbours::All => f.write_str("all"),
            Neighbours::None => f.write_str("none"),
            Neighbours::Nearest(k) => write!(f, "the {k} nearest"),
        }
    }
}

/// The options as one sentence.
pub fn write_options(out: &mut impl Write, o: &LawOptions) -> fmt::Result {
    write!(
        out,
        "reverse `{}`, arrival radius {} units, neighbours: {}",
        o.reverse.name(),
        o.arrival_units,
        Neigh(o.neighbours)
    )
}

fn write_range(out: &mut impl Write, p: &Param) -> fmt::Result {
    if p.choices.is_empty() {
        return write!(out, "{}..={}", p.min, p.max);
    }
    for (i, c) in p.choices.iter().enumerate() {
        write!(out, "{}`{c}`", if i == 0 { "" } else { ", " })?;
    }
    Ok(())
}

fn write_default(out: &mut impl Write, p: &Param) -> fmt::Result {
    match p.default {
        None => out.write_str("required"),
        Some(d) => match usize::try_from(d).ok().and_then(|i| p.choices.get(i)) {
            Some(c) => write!(out, "`{c}`"),
            None => write!(out, "{d}"),
        },
    }
}

/// One law's reference.
pub fn write_law(out: &mut impl Write, law: &LawInfo) -> fmt::Result {
    writeln!(out, "#### `{}` (ID {})\n", law.name, law.id)?;
    writeln!(out, "{}\n", law.summary)?;
    if law.params.is_empty() {
        writeln!(out, "No parameters.\n")?;
    } else {
        writeln!(out, "| parameter | unit | values | default | meaning |")?;
        writeln!(out, "|---|---|---|---|---|")?;
        for p in law.params {
            write!(out, "| `{}` | {} | ", p.name, p.unit)?;
            write_range(out, p)?;
            out.write_str(" | ")?;
            write_default(out, p)?;
            writeln!(out, " | {} |", p.doc)?;
        }
        writeln!(out)?;
    }
    out.write_str("Default options: ")?;
    write_options(out, &law.options)?;
    write!(out, ". Group command body: {} bytes.", law.wire_len())?;
    if !law.drives {
        out.write_str(
            " The controller only reports; another part of the firmware drives the car.",
        )?;
    }
    if !law.converges {
        out.write_str(
            " It never reports convergence: an experiment's phase of it ends at its `timeout_s` (or the next phase's `start_s`), as completed.",
        )?;
    }
    writeln!(out)
}

/// Every registered law's reference, in the order of the list.
pub fn write_markdown(out: &mut impl Write) -> fmt::Result {
    for (i, law) in LAWS.iter().enumerate() {
        if i > 0 {
            writeln!(out)?;
        }
        write_law(out, law)?;
    }
    Ok(())
}
