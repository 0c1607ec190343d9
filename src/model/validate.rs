//! Validation of a `CameraModel`: every number finite and in range, errors naming
//! the JSON field (`noise.levels[2].slope[1]`), so bad files never reach the GPU.

use super::*;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ModelError {
    #[error("camera model JSON could not be parsed: {0}")]
    Parse(String),
    #[error("camera model field `{field}`: {problem}")]
    Field { field: String, problem: String },
}

fn bad(field: impl Into<String>, problem: impl Into<String>) -> ModelError {
    ModelError::Field { field: field.into(), problem: problem.into() }
}

fn finite(field: &str, v: f32) -> Result<(), ModelError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(bad(field, format!("must be a finite number, got {v}")))
    }
}

fn finite_opt(field: &str, v: Option<f64>) -> Result<(), ModelError> {
    match v {
        Some(x) if !x.is_finite() => Err(bad(field, format!("must be finite, got {x}"))),
        _ => Ok(()),
    }
}

fn check_diagnostics(prefix: &str, d: &Diagnostics) -> Result<(), ModelError> {
    finite_opt(&format!("{prefix}.diagnostics.residual_before"), d.residual_before)?;
    finite_opt(&format!("{prefix}.diagnostics.residual_after"), d.residual_after)?;
    finite_opt(&format!("{prefix}.diagnostics.stderr"), d.stderr)?;
    if !d.fit_time_s.is_finite() || d.fit_time_s < 0.0 {
        return Err(bad(format!("{prefix}.diagnostics.fit_time_s"), "must be finite and ≥ 0"));
    }
    Ok(())
}

impl CameraModel {
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.schema != SCHEMA {
            return Err(bad("schema", format!("expected \"{SCHEMA}\", got \"{}\"", self.schema)));
        }
        let r = &self.reference;
        if r.width == 0 || r.height == 0 {
            return Err(bad("reference.width/height", "must be ≥ 1"));
        }
        if let Some(p) = r.pixels_per_radian {
            if !p.is_finite() || p <= 0.0 {
                return Err(bad("reference.pixels_per_radian", format!("must be finite and > 0, got {p}")));
            }
        }
        if let Some(t) = r.frame_interval_s {
            if !t.is_finite() || t <= 0.0 {
                return Err(bad("reference.frame_interval_s", format!("must be finite and > 0, got {t}")));
            }
        }
        self.validate_noise()?;
        self.validate_motion_blur()?;
        self.validate_dof()?;
        self.validate_colour()?;
        self.validate_vignetting()?;
        self.validate_chromatic()?;
        self.validate_sharpening()
    }

    fn validate_sharpening(&self) -> Result<(), ModelError> {
        let s = &self.sharpening;
        check_diagnostics("sharpening", &s.diagnostics)?;
        for (name, value, [lo, hi]) in [
            ("sharpening.amount", s.amount, SHARPENING_AMOUNT_RANGE),
            ("sharpening.radius_px", s.radius_px, SHARPENING_RADIUS_RANGE_PX),
        ] {
            if let Some(v) = value {
                if !(v.is_finite() && (lo..=hi).contains(&v)) {
                    return Err(bad(name, format!("must be finite and in [{lo}, {hi}], got {v}")));
                }
            }
        }
        if let Some(o) = s.overshoot {
            if !(o.is_finite() && (0.0..=1.0).contains(&o)) {
                return Err(bad("sharpening.overshoot", format!("must be finite and in [0, 1], got {o}")));
            }
        }
        if s.present && (s.amount.is_none() || s.radius_px.is_none()) {
            return Err(bad("sharpening", "amount and radius_px must be set when present is true"));
        }
        Ok(())
    }

    fn validate_chromatic(&self) -> Result<(), ModelError> {
        let c = &self.chromatic_aberration;
        check_diagnostics("chromatic_aberration", &c.diagnostics)?;
        if let Some(s) = c.scale_minus_one {
            let m = MAX_CHROMATIC_SCALE_DEVIATION;
            for (k, v) in s.iter().enumerate() {
                if !(v.is_finite() && v.abs() <= m) {
                    return Err(bad(
                        format!("chromatic_aberration.scale_minus_one[{k}]"),
                        format!("must be finite and within ±{m}, got {v}"),
                    ));
                }
            }
        }
        if c.present && c.scale_minus_one.is_none() {
            return Err(bad("chromatic_aberration", "scale_minus_one must be set when present is true"));
        }
        Ok(())
    }

    fn validate_vignetting(&self) -> Result<(), ModelError> {
        let v = &self.vignetting;
        check_diagnostics("vignetting", &v.diagnostics)?;
        if let Some(a) = v.log_falloff {
            for (k, c) in a.iter().enumerate() {
                if !c.is_finite() {
                    return Err(bad(format!("vignetting.log_falloff[{k}]"), format!("must be finite, got {c}")));
                }
            }
            // What reaches the GPU is V(r) over the frame: bounded at every radius
            // (a quartic's extremes lie between r = 0 and 1 or at them; 65 radii
            // bound it to well under 1% between samples for coefficients this size).
            let [lo, hi] = VIGNETTING_GAIN_RANGE;
            for i in 0..=64 {
                let r = i as f32 / 64.0;
                let g = Vignetting::gain_at(a, r);
                if !(lo..=hi).contains(&g) {
                    return Err(bad(
                        "vignetting.log_falloff",
                        format!("V(r) = {g} at r = {r} is outside [{lo}, {hi}] (coefficients {a:?})"),
                    ));
                }
            }
        }
        if v.present && v.log_falloff.is_none() {
            return Err(bad("vignetting", "log_falloff must be set when present is true"));
        }
        Ok(())
    }

    fn validate_colour(&self) -> Result<(), ModelError> {
        let c = &self.colour;
        check_diagnostics("colour", &c.diagnostics)?;
        let range = 1.0 / MAX_COLOUR_GAIN..=MAX_COLOUR_GAIN;
        if let Some(i) = c.illuminant {
            for (k, v) in i.iter().enumerate() {
                if !v.is_finite() || !range.contains(v) {
                    return Err(bad(
                        format!("colour.illuminant[{k}]"),
                        format!("must be in [1/{MAX_COLOUR_GAIN}, {MAX_COLOUR_GAIN}], got {v}"),
                    ));
                }
            }
        }
        if let Some(e) = c.exposure {
            if !e.is_finite() || !range.contains(&e) {
                return Err(bad(
                    "colour.exposure",
                    format!("must be in [1/{MAX_COLOUR_GAIN}, {MAX_COLOUR_GAIN}], got {e}"),
                ));
            }
        }
        if c.present && (c.illuminant.is_none() || c.exposure.is_none()) {
            return Err(bad("colour", "illuminant and exposure must be set when present is true"));
        }
        // Their product is what reaches the GPU: bounded too.
        for (k, g) in c.gains_or_one().iter().enumerate() {
            if !g.is_finite() || !range.contains(g) {
                return Err(bad(format!("colour gain[{k}]"), format!("exposure × illuminant out of range: {g}")));
            }
        }
        Ok(())
    }

    fn validate_noise(&self) -> Result<(), ModelError> {
        let n = &self.noise;
        check_diagnostics("noise", &n.diagnostics)?;
        if n.levels.len() != NOISE_LEVELS {
            return Err(bad("noise.levels", format!("must have {NOISE_LEVELS} levels, got {}", n.levels.len())));
        }
        let [lo, hi] = n.luminance_range;
        finite("noise.luminance_range[0]", lo)?;
        finite("noise.luminance_range[1]", hi)?;
        if !(0.0..=1.0).contains(&lo) || !(0.0..=1.0).contains(&hi) || lo > hi {
            return Err(bad("noise.luminance_range", format!("must satisfy 0 ≤ lo ≤ hi ≤ 1, got [{lo}, {hi}]")));
        }
        let named = n
            .levels
            .iter()
            .enumerate()
            .map(|(i, l)| (format!("noise.levels[{i}]"), l))
            .chain(n.lowpass.iter().map(|l| ("noise.lowpass".to_string(), l)));
        for (name, level) in named {
            for c in 0..3 {
                finite(&format!("{name}.slope[{c}]"), level.slope[c])?;
                finite(&format!("{name}.intercept[{c}]"), level.intercept[c])?;
                // A std above 1 (the whole signal range) is not a noise model.
                for y in [lo, hi] {
                    let s = level.std(n.form, c, y);
                    if s > 1.0 {
                        return Err(bad(name.clone(), format!("std {s} at luma {y} (channel {c}) exceeds 1")));
                    }
                }
            }
        }
        self.validate_level_sources()
    }

    /// `noise.level_sources`: none, or one per level; a measured level's lumas within
    /// [0, 1] and ordered, at least one bin, a finite non-negative error; a continued
    /// level continues a finer, measured one (what the blind fit writes).
    fn validate_level_sources(&self) -> Result<(), ModelError> {
        let s = &self.noise.level_sources;
        if !s.is_empty() && s.len() != NOISE_LEVELS {
            return Err(bad(
                "noise.level_sources",
                format!("must be empty or have {NOISE_LEVELS} entries, got {}", s.len()),
            ));
        }
        for (l, src) in s.iter().enumerate() {
            let name = format!("noise.level_sources[{l}]");
            match *src {
                LevelSource::Measured { luma: [lo, hi], bins, relative_stderr } => {
                    finite(&format!("{name}.luma[0]"), lo)?;
                    finite(&format!("{name}.luma[1]"), hi)?;
                    if !(0.0..=1.0).contains(&lo) || !(0.0..=1.0).contains(&hi) || lo > hi {
                        return Err(bad(
                            format!("{name}.luma"),
                            format!("must satisfy 0 ≤ lo ≤ hi ≤ 1, got [{lo}, {hi}]"),
                        ));
                    }
                    if bins == 0 {
                        return Err(bad(format!("{name}.bins"), "a measured level has at least one bin"));
                    }
                    finite(&format!("{name}.relative_stderr"), relative_stderr)?;
                    if relative_stderr < 0.0 {
                        return Err(bad(
                            format!("{name}.relative_stderr"),
                            format!("must be ≥ 0, got {relative_stderr}"),
                        ));
                    }
                }
                LevelSource::Continued { from } => {
                    let measured = s.get(from as usize).is_some_and(|f| matches!(f, LevelSource::Measured { .. }));
                    if from as usize >= l || !measured {
                        return Err(bad(
                            format!("{name}.from"),
                            format!("must name a finer, measured level (< {l}), got {from}"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    fn validate_motion_blur(&self) -> Result<(), ModelError> {
        let m = &self.motion_blur;
        check_diagnostics("motion_blur", &m.diagnostics)?;
        match m.exposure {
            Some(l) if !l.is_finite() || !(0.0..=1.0).contains(&l) => {
                Err(bad("motion_blur.exposure", format!("must be in [0, 1], got {l}")))
            }
            None if m.present => Err(bad("motion_blur.exposure", "must be set when present is true")),
            _ => Ok(()),
        }
    }

    fn validate_dof(&self) -> Result<(), ModelError> {
        let d = &self.depth_of_field;
        check_diagnostics("depth_of_field", &d.diagnostics)?;
        let [lo, hi] = d.depth_range;
        finite("depth_of_field.depth_range[0]", lo)?;
        finite("depth_of_field.depth_range[1]", hi)?;
        if lo > hi {
            return Err(bad("depth_of_field.depth_range", format!("lo {lo} > hi {hi}")));
        }
        let Some(curve) = d.curve else {
            if d.present {
                return Err(bad("depth_of_field.curve", "must be set when present is true"));
            }
            return Ok(());
        };
        if d.units == DepthUnits::MetricM && lo <= 0.0 {
            return Err(bad("depth_of_field.depth_range[0]", format!("metric depth must be > 0, got {lo}")));
        }
        match curve {
            DofCurve::Quadratic { a, b, c } => {
                finite("depth_of_field.curve.a", a)?;
                finite("depth_of_field.curve.b", b)?;
                finite("depth_of_field.curve.c", c)?;
            }
            DofCurve::ThinLens { k, focus_depth, c0 } => {
                finite("depth_of_field.curve.k", k)?;
                finite("depth_of_field.curve.focus_depth", focus_depth)?;
                finite("depth_of_field.curve.c0", c0)?;
                if k < 0.0 {
                    return Err(bad("depth_of_field.curve.k", format!("must be ≥ 0, got {k}")));
                }
                if d.units == DepthUnits::MetricM && focus_depth <= 0.0 {
                    return Err(bad("depth_of_field.curve.focus_depth", format!("must be > 0 m, got {focus_depth}")));
                }
            }
            DofCurve::Constant { c } => {
                finite("depth_of_field.curve.c", c)?;
                if !(0.0..=MAX_DOF_SIGMA_PX).contains(&c) {
                    return Err(bad("depth_of_field.curve.c", format!("must be in [0, {MAX_DOF_SIGMA_PX}], got {c}")));
                }
            }
        }
        Ok(())
    }
}
