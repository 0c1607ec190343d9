//! The headset's status panel on the CPU: what the calibration is doing, as lines
//! of text (`model_lines`, `CalibrationStatus::lines`), drawn with the bundled
//! DejaVu Sans into an RGBA8 image (`draw`) that the XR app shows as a quad layer
//! (`xr::panel`). Pure CPU and deterministic: a test draws the same lines and
//! compares them with what the runtime was handed, byte for byte.

use crate::model::{CameraModel, Diagnostics, Status};
use crate::worker::{Phase, WorkerStatus};
use ab_glyph::{Font, FontRef, PxScale, ScaleFont};
use std::time::Instant;

/// The panel texture's size (px): 0.5 m wide at 0.9 m in front of the eyes
/// (`xr::panel`) covers ≈ 31°, about 650 display pixels on a Quest 3 (≈ 21 px per
/// degree at the centre), so 1024 texels keep the text sharp when magnified a little.
pub const PANEL_SIZE: (u32, u32) = (1024, 512);
/// Text height (px) and line pitch: 13 lines fit.
const TEXT_PX: f32 = 30.0;
const LINE_PX: u32 = 38;
const MARGIN_PX: u32 = 16;
/// Straight-alpha sRGB colours: a dark translucent card, white text, and a
/// warning colour for lines that start with `!`.
const BACKGROUND: [u8; 4] = [18, 20, 26, 215];
const TEXT: [u8; 3] = [240, 240, 240];
const WARN: [u8; 3] = [255, 190, 90];

/// The bundled font (assets/fonts, Bitstream Vera licence): no system font lookup
/// on the headset or a fresh machine.
const FONT_TTF: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Draw `lines` (top to bottom; a line starting with `!` in the warning colour,
/// without the `!`) into a `width`×`height` RGBA8 image, sRGB-encoded with straight
/// alpha, rows top-down. Lines that do not fit are cut at the edge; lines below
/// the last that fits are left out.
pub fn draw(lines: &[String], width: u32, height: u32) -> Vec<u8> {
    let mut rgba: Vec<u8> = BACKGROUND.repeat((width * height) as usize);
    // The bundled font always parses (a unit test holds it); were it not to, the
    // panel shows an empty card rather than failing the frame loop.
    let Ok(font) = FontRef::try_from_slice(FONT_TTF) else { return rgba };
    let scaled = font.as_scaled(PxScale::from(TEXT_PX));
    for (row, line) in lines.iter().enumerate() {
        let base_y = MARGIN_PX + row as u32 * LINE_PX;
        if base_y + LINE_PX > height {
            break;
        }
        let (text, colour) = match line.strip_prefix('!') {
            Some(rest) => (rest, WARN),
            None => (line.as_str(), TEXT),
        };
        let baseline = base_y as f32 + scaled.ascent();
        let mut x = MARGIN_PX as f32;
        let mut previous = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(p) = previous {
                x += scaled.kern(p, id);
            }
            previous = Some(id);
            let glyph = id.with_scale_and_position(PxScale::from(TEXT_PX), ab_glyph::point(x, baseline));
            x += scaled.h_advance(id);
            if x > (width - MARGIN_PX) as f32 {
                break;
            }
            let Some(outline) = font.outline_glyph(glyph) else { continue };
            let bounds = outline.px_bounds();
            outline.draw(|gx, gy, coverage| {
                let (px, py) = (bounds.min.x as i64 + gx as i64, bounds.min.y as i64 + gy as i64);
                if px < 0 || py < 0 || px >= width as i64 || py >= height as i64 {
                    return;
                }
                let a = coverage.clamp(0.0, 1.0);
                let i = ((py as u32 * width + px as u32) * 4) as usize;
                // "Over" in straight alpha, on sRGB values (text on a card: the
                // difference from blending in linear light is a hair of weight).
                let (ba, ta) = (rgba[i + 3] as f32 / 255.0, a);
                let out_a = ta + ba * (1.0 - ta);
                for k in 0..3 {
                    let v = (colour[k] as f32 * ta + rgba[i + k] as f32 * ba * (1.0 - ta)) / out_a.max(1e-6);
                    rgba[i + k] = v.round().clamp(0.0, 255.0) as u8;
                }
                rgba[i + 3] = (out_a * 255.0).round() as u8;
            });
        }
    }
    rgba
}

fn status_word(d: &Diagnostics) -> &'static str {
    d.status_str()
}

/// "± e" when the diagnostics carry an error.
fn plus_minus(d: &Diagnostics, scale: f64, unit: &str) -> String {
    match d.stderr {
        Some(e) if e.is_finite() => format!(" ± {:.2}{unit}", e * scale),
        _ => String::new(),
    }
}

/// One line per effect and the model's identity: what the renderer applies now.
/// `age_s`: time since this generation was published (None: not known).
pub fn model_lines(model: &CameraModel, generation: u64, age_s: Option<f64>) -> Vec<String> {
    let mut out = vec![];
    let age = age_s.map_or(String::new(), |a| format!(", {a:.1} s old"));
    out.push(format!("model generation {generation}{age}"));
    let n = &model.noise;
    let noise = match crate::model::compare::noise_headline(n) {
        Some(std) => format!(
            "noise: {} · σ {:.2}/255 at mid grey{}",
            status_word(&n.diagnostics),
            std * 255.0,
            plus_minus(&n.diagnostics, 100.0, " %")
        ),
        None => format!("noise: {}", status_word(&n.diagnostics)),
    };
    out.push(noise);
    let mb = &model.motion_blur;
    out.push(match (mb.present, mb.exposure) {
        (true, Some(l)) => format!(
            "motion blur: {} · exposure λ {l:.3}{}",
            status_word(&mb.diagnostics),
            plus_minus(&mb.diagnostics, 1.0, "")
        ),
        (false, Some(l)) => format!("motion blur: {} (last λ {l:.3}, not applied)", status_word(&mb.diagnostics)),
        _ => format!("motion blur: {}", status_word(&mb.diagnostics)),
    });
    let dof = &model.depth_of_field;
    out.push(if dof.present && dof.curve.is_some() {
        let [z0, z1] = dof.depth_range;
        let (near, far) = (dof.sigma_px(z0), dof.sigma_px(z1));
        format!(
            "depth of field: {} · δ {near:.2} px at {z0:.2}, {far:.2} px at {z1:.2} {}{}",
            status_word(&dof.diagnostics),
            match dof.units {
                crate::model::DepthUnits::MetricM => "m",
                crate::model::DepthUnits::RelativeInverse => "(relative inverse depth)",
            },
            plus_minus(&dof.diagnostics, 1.0, " px")
        )
    } else {
        format!("depth of field: {}", status_word(&dof.diagnostics))
    });
    // Not identifiable or not fitted: say why (the scene cannot show it yet).
    for (name, d) in [("noise", &n.diagnostics), ("motion blur", &mb.diagnostics), ("depth of field", &dof.diagnostics)]
    {
        if matches!(d.status, Status::NotIdentifiable) && !d.reason.is_empty() {
            out.push(format!("  {name}: {}", shorten(&d.reason, 70)));
        }
    }
    out
}

fn shorten(s: &str, max_chars: usize) -> String {
    if s.chars().count() <= max_chars {
        s.to_string()
    } else {
        let cut: String = s.chars().take(max_chars - 1).collect();
        format!("{cut}…")
    }
}

/// The camera and calibration side of the panel, kept by the app's camera thread
/// and refreshed at the panel's rate: camera frames per second delivered, taken by
/// the worker and dropped (the rates over the last refresh), the calibration's
/// phase and the recording.
pub struct CalibrationStatus {
    tier: String,
    last: Option<(Instant, u64, u64)>,
    rates: Option<(f64, f64)>,
}

impl CalibrationStatus {
    pub fn new(tier: &str) -> Self {
        Self { tier: tier.to_string(), last: None, rates: None }
    }

    /// The lines for the camera's `frames` delivered so far, the worker's counters
    /// and the recording in progress (its folder), at `now`.
    pub fn lines(
        &mut self,
        now: Instant,
        frames: u64,
        worker: &WorkerStatus,
        recording: Option<&std::path::Path>,
    ) -> Vec<String> {
        let taken = worker.submitted.saturating_sub(worker.dropped);
        if let Some((t, f0, k0)) = self.last {
            let dt = now.saturating_duration_since(t).as_secs_f64();
            if dt >= 0.25 {
                let delivered = frames.saturating_sub(f0) as f64 / dt;
                let took = taken.saturating_sub(k0) as f64 / dt;
                self.rates = Some((delivered, took));
                self.last = Some((now, frames, taken));
            }
        } else {
            self.last = Some((now, frames, taken));
        }
        let mut out = vec![];
        out.push(match self.rates {
            Some((delivered, took)) => format!(
                "{} tier · camera {delivered:.1} fps · taken {took:.1}/s · dropped {:.1}/s",
                self.tier,
                (delivered - took).max(0.0)
            ),
            None => format!("{} tier · camera: measuring", self.tier),
        });
        out.push(match worker.phase {
            Phase::Waiting => "!calibration: waiting for camera frames".to_string(),
            Phase::Burst { elapsed_s, of_s, after_change: false } => {
                format!("!start-up calibration: look around ({:.1} of {of_s:.1} s)", elapsed_s.clamp(0.0, of_s))
            }
            Phase::Burst { elapsed_s, of_s, after_change: true } => {
                format!("!camera change detected: recalibrating ({:.1} of {of_s:.1} s)", elapsed_s.clamp(0.0, of_s))
            }
            Phase::Steady => format!(
                "calibrated · {} frames fitted, {} models published{}",
                worker.processed,
                worker.published,
                if worker.errors > 0 { format!(", {} refused", worker.errors) } else { String::new() }
            ),
        });
        out.push(match recording {
            Some(dir) => format!(
                "!recording into {} (left stick click stops)",
                dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned())
            ),
            None => "not recording (left stick click records)".to_string(),
        });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_font_parses() {
        assert!(FontRef::try_from_slice(FONT_TTF).is_ok());
    }

    /// Text lands where its line is and nowhere else; the card elsewhere keeps its
    /// colour; the same lines draw the same bytes.
    #[test]
    fn draws_lines_on_the_card() {
        let (w, h) = (320, 160);
        let lines = vec!["Hg noise: present".to_string(), String::new(), "!warning".to_string()];
        let img = draw(&lines, w, h);
        assert_eq!(img.len(), (w * h * 4) as usize);
        assert_eq!(img, draw(&lines, w, h));
        let differs = |y0: u32, y1: u32| -> usize {
            (y0..y1)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    let i = ((y * w + x) * 4) as usize;
                    img[i..i + 4] != BACKGROUND
                })
                .count()
        };
        let line = |k: u32| (MARGIN_PX + k * LINE_PX, MARGIN_PX + (k + 1) * LINE_PX);
        let (a0, a1) = line(0);
        assert!(differs(a0, a1) > 500, "first line drew {} pixels", differs(a0, a1));
        let (b0, b1) = line(1);
        // The empty line: nothing but descenders of the line above may reach in.
        assert!(differs(b0 + 12, b1) == 0, "empty line drew {}", differs(b0 + 12, b1));
        let (c0, c1) = line(2);
        assert!(differs(c0, c1) > 100);
        // The warning line is drawn in the warning colour, without its '!'.
        let warn_px = (c0..c1)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let i = ((y * w + x) * 4) as usize;
                img[i..i + 3] == WARN
            })
            .count();
        assert!(warn_px > 20, "{warn_px} pixels in the warning colour");
        // Below the lines: the card.
        assert_eq!(differs(c1 + 4, h), 0);
    }

    /// A line longer than the panel is cut at the margin; lines beyond the last
    /// row are left out; neither panics.
    #[test]
    fn long_and_many_lines_are_cut() {
        let (w, h) = (200, 100);
        let lines: Vec<String> = (0..20).map(|i| format!("line {i} {}", "W".repeat(80))).collect();
        let img = draw(&lines, w, h);
        for y in 0..h {
            for x in w - MARGIN_PX + 2..w {
                let i = ((y * w + x) * 4) as usize;
                assert_eq!(img[i..i + 4], BACKGROUND, "text past the margin at ({x}, {y})");
            }
        }
    }

    #[test]
    fn model_lines_name_each_effect_and_its_state() {
        use crate::model::{DepthOfField, DepthUnits, DofCurve, DofKernel, MotionBlur};
        let mut m = CameraModel::empty(1280, 960);
        m.noise = crate::synth::white_sensor_noise([2e-5, 1.2e-5, 4e-5], [8e-4, 5e-4, 1.2e-3], [0.0, 1.0]);
        m.motion_blur = MotionBlur { present: true, exposure: Some(0.4), diagnostics: Diagnostics::not_fitted("") };
        m.depth_of_field = DepthOfField {
            present: true,
            units: DepthUnits::MetricM,
            curve: Some(DofCurve::ThinLens { k: 1.5, focus_depth: 1.5, c0: 0.2 }),
            depth_range: [0.3, 10.0],
            kernel: DofKernel::Gaussian,
            diagnostics: Diagnostics::not_fitted(""),
        };
        m.motion_blur.diagnostics.status = Status::Present;
        m.motion_blur.diagnostics.stderr = Some(0.021);
        m.depth_of_field.diagnostics.status = Status::NotIdentifiable;
        m.depth_of_field.diagnostics.reason = "no depth edges in view".into();
        let lines = model_lines(&m, 7, Some(1.25));
        assert_eq!(lines[0], "model generation 7, 1.2 s old");
        assert!(lines[1].starts_with("noise: not fitted · σ "), "{}", lines[1]);
        assert_eq!(lines[2], "motion blur: present · exposure λ 0.400 ± 0.02");
        assert!(lines[3].starts_with("depth of field: not identifiable · δ "), "{}", lines[3]);
        assert_eq!(lines[4], "  depth of field: no depth edges in view");
        m.motion_blur.present = false;
        assert_eq!(model_lines(&m, 7, None)[2], "motion blur: present (last λ 0.400, not applied)");
    }

    #[test]
    fn calibration_lines_rate_and_phase() {
        let mut s = CalibrationStatus::new("fast");
        let t0 = Instant::now();
        let mut w = WorkerStatus {
            phase: Phase::Burst { elapsed_s: 0.4, of_s: 1.0, after_change: false },
            ..Default::default()
        };
        let first = s.lines(t0, 0, &w, None);
        assert_eq!(first[0], "fast tier · camera: measuring");
        assert_eq!(first[1], "!start-up calibration: look around (0.4 of 1.0 s)");
        assert_eq!(first[2], "not recording (left stick click records)");
        (w.submitted, w.dropped, w.processed, w.published, w.phase) = (12, 2, 10, 4, Phase::Steady);
        let second = s.lines(t0 + std::time::Duration::from_secs(1), 30, &w, Some(std::path::Path::new("/x/rec-5")));
        assert_eq!(second[0], "fast tier · camera 30.0 fps · taken 10.0/s · dropped 20.0/s");
        assert_eq!(second[1], "calibrated · 10 frames fitted, 4 models published");
        assert_eq!(second[2], "!recording into rec-5 (left stick click stops)");
    }
}
