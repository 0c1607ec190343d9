//! `acf_shape`'s tests: known streaks on synthetic textures, the refusals, the dip.

use super::*;

/// A smooth random texture (sum of random Gaussian blobs), isotropic on average.
fn texture(w: usize, h: usize, seed: u64) -> Plane {
    blobs(w, h, seed, 40, 4.0, 1.0)
}

/// Strokes: smaller blobs stretched `k`× along y (k < 1: along x).
fn strokes(w: usize, h: usize, seed: u64, k: f32) -> Plane {
    blobs(w, h, seed, 60, 2.0, k)
}

/// One Gaussian blob per `px_per_blob` pixels, radius 1…1 + `r_span` px along x
/// and `k`× that along y, contrast ±0.15 on 0.5.
fn blobs(w: usize, h: usize, seed: u64, px_per_blob: usize, r_span: f32, k: f32) -> Plane {
    let mut s = seed;
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 33) as f64 / (1u64 << 31) as f64) as f32
    };
    let mut p = Plane::new(w, h, 0.5);
    for _ in 0..(w * h / px_per_blob) {
        let (x0, y0) = (rnd() * w as f32, rnd() * h as f32);
        let r = 1.0 + r_span * rnd();
        let (rx, ry) = (r, r * k);
        let a = 0.3 * (rnd() - 0.5);
        let (xa, xb) = ((x0 - 3.0 * rx).max(0.0) as usize, ((x0 + 3.0 * rx) as usize).min(w - 1));
        let (ya, yb) = ((y0 - 3.0 * ry).max(0.0) as usize, ((y0 + 3.0 * ry) as usize).min(h - 1));
        for y in ya..=yb {
            for x in xa..=xb {
                let d2 = ((x as f32 - x0) / rx).powi(2) + ((y as f32 - y0) / ry).powi(2);
                p.data[y * w + x] += a * (-0.5 * d2).exp();
            }
        }
    }
    p
}

/// A box streak of `len` px along (cos, sin) `deg`, sampled every 0.25 px.
fn streak(p: &Plane, len: f32, deg: f32) -> Plane {
    if len <= 0.0 {
        return p.clone();
    }
    let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
    let n = (len * 4.0).ceil() as usize;
    let mut out = Plane::new(p.width, p.height, 0.0);
    for y in 0..p.height {
        for x in 0..p.width {
            let mut acc = 0.0;
            for i in 0..n {
                let t = ((i as f32 + 0.5) / n as f32 - 0.5) * len;
                acc += p.sample_bilinear(x as f32 + t * c, y as f32 + t * s);
            }
            out.data[y * p.width + x] = acc / n as f32;
        }
    }
    out
}

fn uniform(w: usize, h: usize, deg: f32, speed: f32) -> Flow {
    let a = deg.to_radians();
    Flow::uniform(w, h, speed * a.cos(), speed * a.sin())
}

/// Box streaks of 0, 8 and 20 px at 0°, 90° and 30° on an isotropic texture read
/// within 1.5 px (the candidate grid is 1 px, parabola-refined; the streak is
/// drawn by a different sampler than the box the shape assumes).
#[test]
fn streaks_on_an_isotropic_texture_read_their_length() {
    let base = texture(400, 320, 7);
    for deg in [0.0f32, 90.0, 30.0] {
        for len in [0.0f32, 8.0, 20.0] {
            let img = streak(&base, len, deg);
            let got = acf_shape(&img, &uniform(400, 320, deg, 40.0)).expect("read");
            assert!((got.length_px - len).abs() <= 1.5, "{deg}° {len} px: read {:?}", got);
            assert!((got.lambda - got.length_px / 40.0).abs() < 1e-6);
        }
    }
}

/// Strokes across the flow (blobs 3× longer across than along, like a text
/// page's letters under a vertical streak) bias the shape: a 32 px streak read
/// 28.9 px at 0°. The along-flow dip, read near it, sits within 1 px of the
/// streak at 0° and 90° (the dip's lag is the box's length for a texture this much
/// narrower than it; 1 px: the streak's own 0.25 px sampling and the parabola).
/// Under 20 px (`MIN_DIP_LENGTH_PX`) no dip is read.
#[test]
fn the_dip_reads_a_long_streak_over_strokes_across_it() {
    for (deg, k) in [(0.0f32, 3.0f32), (90.0, 1.0 / 3.0)] {
        let base = strokes(480, 400, 5, k);
        let img = streak(&base, 32.0, deg);
        let got = acf_shape(&img, &uniform(480, 400, deg, 50.0)).expect("read");
        let dip = got.dip.unwrap_or_else(|| panic!("{deg}°: no dip in {got:?}"));
        assert!((dip.lag_px - 32.0).abs() <= 1.0, "{deg}°: {got:?}");
        assert!(dip.along < dip.across - MIN_DIP_EXCESS, "{dip:?}");
        let short = acf_shape(&streak(&base, 12.0, deg), &uniform(480, 400, deg, 50.0)).expect("read");
        assert!(short.dip.is_none(), "{deg}°: {short:?}");
    }
}

/// `MAX_DIP_LENGTH_PX` is the longest length whose window fits the lags.
#[test]
fn the_longest_checked_length_fits_the_lags() {
    let l = MAX_DIP_LENGTH_PX as f64;
    assert!((l * DIP_WINDOW).ceil() as usize <= MAX_LAG_PX);
    assert!(((l + 1.0) * DIP_WINDOW).ceil() as usize > MAX_LAG_PX);
}

/// `along_dip` on curves of a known form: a box of 30 px over a sharp texture of
/// R(t) = exp(−t²/8) reads 30 px (the form's exact minimum, to the parabola's
/// 0.05 px); the same dip across the flow as along (a texture's period, not a
/// streak) reads none; nor does a length under `MIN_DIP_LENGTH_PX`, nor a
/// window whose minimum sits on its edge.
#[test]
fn along_dip_on_known_curves() {
    let r = |t: f64| (-t * t / 8.0).exp();
    let streak =
        |l: f64| -> Vec<f64> { (0..=80).map(|t| 2.0 * r(t as f64) - r(t as f64 - l) - r(t as f64 + l)).collect() };
    let across: Vec<f64> = (0..=80).map(|t| r(t as f64)).collect();
    let d = along_dip(&streak(30.0), &across, 27.0, MIN_DIP_LENGTH_PX).expect("dip");
    assert!((d.lag_px - 30.0).abs() < 0.05, "{d:?}");
    assert!((d.along + 0.5).abs() < 0.01, "{d:?}");
    assert!(along_dip(&streak(30.0), &streak(30.0), 27.0, MIN_DIP_LENGTH_PX).is_none());
    assert!(along_dip(&streak(15.0), &across, 15.0, MIN_DIP_LENGTH_PX).is_none());
    // The window [20/1.4, 28] ends below a 40 px dip: its minimum is the edge.
    assert!(along_dip(&streak(40.0), &across, 20.0, MIN_DIP_LENGTH_PX).is_none());
}

/// White noise (σ 0.02 on a texture of contrast ~0.1) is subtracted, as the
/// crop's bilinear sampling correlates it at 30°: a 12 px streak still reads
/// within 1.5 px, and no streak reads below 2 px. (Measured without the
/// subtraction at 0°: no streak read 2.5 px.)
#[test]
fn white_noise_is_subtracted() {
    let base = texture(400, 320, 11);
    let mut s = 3u64;
    for (len, deg) in [(0.0f32, 0.0f32), (12.0, 0.0), (0.0, 30.0), (12.0, 30.0)] {
        let mut img = streak(&base, len, deg);
        for v in &mut img.data {
            // Sum of 4 uniforms: near-Gaussian, σ = 0.02.
            let mut u = 0.0;
            for _ in 0..4 {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                u += (s >> 33) as f32 / (1u64 << 31) as f32 - 0.5;
            }
            *v += u * 0.02 * 3.0f32.sqrt();
        }
        let got = acf_shape(&img, &uniform(400, 320, deg, 40.0)).expect("read");
        if len == 0.0 {
            assert!(got.length_px < 2.0, "{got:?}");
        } else {
            assert!((got.length_px - len).abs() <= 1.5, "{got:?}");
        }
    }
}

/// A flow whose speed varies ±40% across the frame (a wide-angle head turn's
/// centre against its edges) is read over a central crop where it holds one
/// length: a 16 px streak within 1.5 px, the crop's median speed within 5%.
#[test]
fn a_central_crop_holds_one_length_where_the_frame_does_not() {
    let (w, h) = (480usize, 360usize);
    let img = streak(&texture(w, h, 13), 16.0, 0.0);
    let mut flow = uniform(w, h, 0.0, 40.0);
    for y in 0..h {
        for x in 0..w {
            flow.dx[y * w + x] = 40.0 * (0.6 + 0.8 * x as f32 / w as f32);
        }
    }
    let got = acf_shape(&img, &flow).expect("read over the centre");
    assert!((got.length_px - 16.0).abs() <= 1.5, "{got:?}");
    assert!((got.speed_px / 40.0 - 1.0).abs() <= 0.05, "{got:?}");
    assert!(got.crop.0 < 440, "{got:?}");
}

/// One streak length is assumed: a flow turning through 90° across the frame, or
/// speeding up 9× across it, is not read even over the centre; nor a frame too
/// small for the lags.
#[test]
fn incoherent_flow_and_small_frames_are_refused() {
    let img = texture(400, 320, 5);
    let mut turning = uniform(400, 320, 0.0, 20.0);
    for y in 0..320 {
        for x in 0..400 {
            let a = (x as f32 / 400.0) * std::f32::consts::FRAC_PI_2;
            turning.dx[y * 400 + x] = 20.0 * a.cos();
            turning.dy[y * 400 + x] = 20.0 * a.sin();
        }
    }
    let e = acf_shape(&img, &turning).unwrap_err();
    assert!(e.why().contains("direction"), "{e}");
    // 5–45 px/frame across the frame: 15–35 over its central half.
    let mut faster = uniform(400, 320, 0.0, 20.0);
    for x in 0..400 {
        for y in 0..320 {
            faster.dx[y * 400 + x] = 5.0 + 40.0 * x as f32 / 400.0;
        }
    }
    let e = acf_shape(&img, &faster).unwrap_err();
    assert!(e.why().contains("speed"), "{e}");
    let small = texture(200, 150, 5);
    let e = acf_shape(&small, &uniform(200, 150, 0.0, 20.0)).unwrap_err();
    assert!(e.why().contains("crop"), "{e}");
}

/// A frame of noise alone (no texture), or flat: not read, never a streak of 0.
#[test]
fn noise_alone_is_not_read() {
    let mut img = Plane::new(400, 320, 0.5);
    let flow = uniform(400, 320, 30.0, 40.0);
    let e = acf_shape(&img, &flow).unwrap_err();
    assert!(e.why().contains("no texture"), "{e}");
    let mut s = 9u64;
    for v in &mut img.data {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        *v += 0.02 * ((s >> 33) as f32 / (1u64 << 31) as f32 - 0.5);
    }
    let e = acf_shape(&img, &flow).unwrap_err();
    println!("{e}");
    assert!(e.why().contains("no texture"), "{e}");
}

#[test]
fn kernels_and_sizes() {
    let k = box_kernel(4.0);
    assert_eq!(k.len(), 5);
    assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert!((k[0] - 0.125).abs() < 1e-12 && (k[2] - 0.25).abs() < 1e-12);
    let r = kernel_autocorrelation(&k);
    assert_eq!(r.len(), 9);
    assert!((r.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert_eq!(fft_size(721), 729);
    assert_eq!(fft_size(720), 720);
    assert_eq!(fft_size(7), 8);
}

/// Smooth shading (a colour wheel's: luma varying with the angle about the centre, no
/// edges) matches every streak length about as well as none, so its best length of 0
/// is not a reading: without a streak the shape refuses (without `MIN_ZERO_RISE` it
/// reads 0 px — and calls a colour wheel's 6–24 px box streaks absent);
/// with a 12 px streak at 30° it may read a length (9.0 px here) but never none. An
/// isotropic texture without a streak still reads 0
/// (`streaks_on_an_isotropic_texture_read_their_length`).
#[test]
fn smooth_shading_does_not_read_as_no_streak() {
    let (w, h) = (400, 320);
    let wheel = Plane::from_vec(
        w,
        h,
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 0.5 * w as f32, (i / w) as f32 - 0.5 * h as f32);
                0.5 + 0.3 * y.atan2(x).sin()
            })
            .collect(),
    );
    for len in [0.0f32, 12.0] {
        let img = streak(&wheel, len, 30.0);
        match acf_shape(&img, &uniform(w, h, 30.0, 40.0)) {
            Err(why) => assert!(why.why().contains("does not tell a streak from none"), "{len} px: {why}"),
            Ok(got) => {
                assert!(len > 0.0 && got.length_px >= 1.0, "{len} px: read {} px on smooth shading", got.length_px)
            }
        }
    }
}
