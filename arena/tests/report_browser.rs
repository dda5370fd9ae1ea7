//! `report.html` as a person sees it: a run's report opened in headless Chromium (no network,
//! a throw-away profile) shows every car, each in its colour (the legend of the trajectory
//! plot and the cars table), and every plot file is there. Skipped, saying so, where
//! Chromium is not installed (`cargo xtask test` installs Debian's `chromium`).

#[path = "arena_common.rs"]
mod common;

use arena::experiment::{self, Experiment};
use arena::plot::colour_of;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

const EXPERIMENT: &str = r#"
name = "report"
duration_s = 4
seed = 5
[[cars]]
id = 3
x = 120
y = 150
heading_mrad = 785
[[cars]]
id = 5
x = 480
y = 150
heading_mrad = 2356
[[cars]]
id = 7
x = 300
y = 600
heading_mrad = 4712
[[cars]]
id = 9
x = 300
y = 300
heading_mrad = 1571
[maneuver]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
"#;

/// Debian's Chromium, if installed.
fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser"].iter().find_map(|name| {
        std::env::split_paths(&path)
            .map(|d| d.join(name))
            .find(|p| p.is_file())
    })
}

/// Takes a screenshot of `page` (`width` x `height` px) into `png`.
fn screenshot(browser: &Path, page: &Path, png: &Path, profile: &Path, size: (u32, u32)) {
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!("--window-size={},{}", size.0, size.1))
        .arg(format!("file://{}", page.display()))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromium starts");
    let end = Instant::now() + Duration::from_secs(120);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "chromium: {status}");
            break;
        }
        if Instant::now() > end {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium took over 120 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Pixels of a PNG as RGB triples.
fn pixels(png: &Path) -> Vec<[u8; 3]> {
    let decoder = png::Decoder::new(std::fs::File::open(png).expect("screenshot written"));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("PNG pixels");
    let step = match info.color_type {
        png::ColorType::Rgba => 4,
        png::ColorType::Rgb => 3,
        other => panic!("unexpected screenshot colour type {other:?}"),
    };
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf[..info.buffer_size()]
        .chunks_exact(step)
        .map(|p| [p[0], p[1], p[2]])
        .collect()
}

#[test]
fn report_shows_every_car_in_a_headless_browser() {
    let Some(browser) = chromium() else {
        eprintln!(
            "SKIPPED report_shows_every_car_in_a_headless_browser: chromium is not installed \
             (`cargo xtask test` installs it; by hand: apt-get install chromium)"
        );
        return;
    };
    let exp = Experiment::parse(EXPERIMENT).unwrap();
    let elf = exp.engine.default_firmware().expect("firmware ELF");
    let out = std::env::temp_dir().join(format!("arena-report-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cancel = AtomicBool::new(false);
    experiment::run(&exp, &elf, &out, &mut |_| {}, &cancel).expect("experiment runs");
    for plot in ["trajectories", "phase_error", "separation", "radio"] {
        for ext in ["svg", "png"] {
            assert!(out.join(format!("{plot}.{ext}")).is_file(), "{plot}.{ext}");
        }
    }
    let page = out.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(
        !html.contains("http://") && !html.contains("https://") && !html.contains("<script"),
        "the report is self-contained"
    );
    assert_eq!(html.matches("<img src=\"data:image/png;base64,").count(), 4);
    let shot = out.join("screenshot.png");
    screenshot(&browser, &page, &shot, &out.join("profile"), (1400, 1800));
    let px = pixels(&shot);
    assert_eq!(px.len(), 1400 * 1800);
    for (k, car) in exp.cars.iter().enumerate() {
        let (r, g, b) = colour_of(k);
        let n = px.iter().filter(|p| **p == [r, g, b]).count();
        eprintln!("car {}: {n} pixels of #{r:02x}{g:02x}{b:02x}", car.id);
        // The legend's swatch (14 x 14) and the table's (16 x 16), at least.
        assert!(
            n >= 300,
            "car {} (#{r:02x}{g:02x}{b:02x}): only {n} pixels",
            car.id
        );
    }
    let white = px.iter().filter(|p| **p == [255, 255, 255]).count();
    assert!(white < px.len() * 98 / 100, "the page is not blank");
    let _ = std::fs::remove_dir_all(&out);
    common::nothing_left_behind();
}
