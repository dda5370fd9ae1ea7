//! `cargo xtask new-program NAME`: a new upper-board program from the template.
//!
//! Copies `ubc-app/src/bin/template.rs` to `ubc-app/src/bin/NAME.rs` with the names changed
//! (`` `template` `` and `--bin template` to the new name, the type `Template` to its
//! CamelCase form) and adds the binary to
//! `ubc-app/Cargo.toml` (it needs a board, like every firmware binary). `cargo xtask fw --bin
//! NAME` then builds it, and an experiment runs it on a car with `firmware = "NAME"`.

use std::fs;
use std::path::Path;

use anyhow::{bail, Context, Result};

/// The template's binary name.
pub const TEMPLATE: &str = "template";

/// Whether `name` can name a program: lowercase ASCII letters, digits and `_`, starting with
/// a letter, at most 40 characters, and not a name the firmware crate uses already.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 40
        && name.as_bytes()[0].is_ascii_lowercase()
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
        && !matches!(name, "ubc_app" | "main" | "build" | "test" | TEMPLATE)
}

/// `square_drive` as `SquareDrive`.
fn camel(name: &str) -> String {
    name.split('_')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// The template with its names changed to `name`.
pub fn render(template: &str, name: &str) -> String {
    template
        .replace("Template", &camel(name))
        .replace(&format!("`{TEMPLATE}`"), &format!("`{name}`"))
        .replace(&format!("--bin {TEMPLATE}"), &format!("--bin {name}"))
}

/// The `[[bin]]` entry of program `name`.
pub fn bin_entry(name: &str) -> String {
    format!(
        "\n[[bin]]\n# A program made by `cargo xtask new-program` (docs/writing-a-program.md).\n\
         name = \"{name}\"\ntest = false\nbench = false\nrequired-features = [\"firmware\"]\n"
    )
}

/// Creates program `name` in the firmware crate at `app` (the `ubc-app` directory).
pub fn create(app: &Path, name: &str) -> Result<()> {
    if !valid_name(name) {
        bail!(
            "`{name}` cannot name a program: use lowercase letters, digits and `_`, starting \
             with a letter (at most 40), and not `{TEMPLATE}`"
        );
    }
    let source = app.join("src/bin").join(format!("{name}.rs"));
    if source.exists() {
        bail!("{} exists already", source.display());
    }
    let manifest = app.join("Cargo.toml");
    let toml =
        fs::read_to_string(&manifest).with_context(|| format!("reading {}", manifest.display()))?;
    if toml.contains(&format!("name = \"{name}\"")) {
        bail!("{} has a binary `{name}` already", manifest.display());
    }
    let template_path = app.join("src/bin").join(format!("{TEMPLATE}.rs"));
    let template = fs::read_to_string(&template_path)
        .with_context(|| format!("reading {}", template_path.display()))?;
    fs::write(&source, render(&template, name))
        .with_context(|| format!("writing {}", source.display()))?;
    fs::write(&manifest, toml + &bin_entry(name))
        .with_context(|| format!("writing {}", manifest.display()))?;
    println!("created {}", source.display());
    println!("added the binary `{name}` to {}", manifest.display());
    println!("build it:    cargo xtask fw --board softcore --bin {name}");
    println!("run it:      firmware = \"{name}\" in an experiment's [[cars]] (docs/writing-a-program.md)");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert!(valid_name("square"));
        assert!(valid_name("square_2"));
        for bad in [
            "", "Square", "2square", "sq-uare", TEMPLATE, "ubc_app", "a b",
        ] {
            assert!(!valid_name(bad), "{bad:?}");
        }
        assert_eq!(camel("square_drive"), "SquareDrive");
        assert_eq!(camel("square"), "Square");
    }

    #[test]
    fn creates_a_program_from_the_template() {
        let dir = std::env::temp_dir().join(format!("xtask-new-program-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(dir.join("src/bin")).unwrap();
        let real = crate::fw::app_dir();
        let template = fs::read_to_string(real.join("src/bin/template.rs")).unwrap();
        fs::write(dir.join("src/bin/template.rs"), &template).unwrap();
        fs::write(dir.join("Cargo.toml"), "[package]\nname = \"ubc-app\"\n").unwrap();
        create(&dir, "square_drive").unwrap();
        let made = fs::read_to_string(dir.join("src/bin/square_drive.rs")).unwrap();
        assert!(made.contains("struct SquareDrive {"), "{made}");
        assert!(made.starts_with("//! `square_drive`: "), "{made}");
        assert!(made.contains("--bin square_drive "));
        assert!(made.contains("from\n//! `ubc-app/src/bin/template.rs`"));
        assert!(!made.contains("Template") && !made.contains("`template`"));
        let toml = fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        assert!(toml.ends_with(&bin_entry("square_drive")));
        // Not twice, and not over the template.
        assert!(create(&dir, "square_drive").is_err());
        assert!(create(&dir, TEMPLATE).is_err());
        fs::remove_dir_all(&dir).unwrap();
        // The template is registered as a firmware binary, like what it makes.
        let toml = fs::read_to_string(real.join("Cargo.toml")).unwrap();
        assert!(toml.contains("name = \"template\""));
    }
}
