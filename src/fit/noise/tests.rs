//! Unit tests of the noise fits: the clip masks and the aligned neighbour's
//! validity (the blind tier), the reference's structure leaks (the accurate tier).

mod valid_mask_tests {
    use super::super::*;

    /// The one-pass lane-wise extremes and counts are the plain two-pass ones:
    /// extremes repeated in different lanes, restarted counts, a tail shorter than
    /// the lanes, an extreme seen only in the tail, and unclipped data (exact).
    #[test]
    fn one_pass_clip_limits_are_the_two_pass_ones() {
        let naive = |ch: &[f32], min_count: usize| {
            let lo = ch.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = ch.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let (nlo, nhi) = (ch.iter().filter(|&&v| v == lo).count(), ch.iter().filter(|&&v| v == hi).count());
            ((lo <= 0.1 && nlo >= min_count).then_some(lo), (hi >= 0.6 && nhi >= min_count).then_some(hi))
        };
        let wavy =
            |n: usize| -> Vec<f32> { (0..n).map(|i| 0.5 + 0.45 * ((i * 7919 % 1013) as f32 / 1013.0 - 0.5)).collect() };
        let mut cases: Vec<Vec<f32>> = vec![wavy(1003), wavy(5), vec![]];
        // Clipped at both ends, in several lanes, with decoys before the clip level.
        let mut clipped = wavy(2051);
        for i in (0..2051).step_by(13) {
            clipped[i] = 1.0;
        }
        for i in (3..2051).step_by(17) {
            clipped[i] = 0.0;
        }
        cases.push(clipped.clone());
        // The maximum seen only in the tail.
        clipped[2050] = 1.5;
        cases.push(clipped);
        for ch in &cases {
            for min_count in [1, 2, 50, 10_000] {
                assert_eq!(
                    channel_clip_limits(ch, min_count),
                    naive(ch, min_count),
                    "len {} min {min_count}",
                    ch.len()
                );
            }
        }
    }

    /// The blind tier's one-pass tile extremes give exactly `clip_limits` and each
    /// channel's `clip_mask_of`: frames whose size is no multiple of the tile
    /// (partial tiles at the right and bottom), clipped at both ends in some
    /// channels, clipped too rarely to count (below 0.05%), and unclipped; the
    /// masks compared through `touches` at every tile and radius the fit uses.
    #[test]
    fn tile_extreme_clip_masks_are_the_two_pass_ones() {
        for (w, h) in [(83usize, 61usize), (64, 48), (9, 7)] {
            let mut img = Rgb::new(w, h, [0.0; 3]);
            for c in 0..3 {
                for (i, v) in img.channels[c].iter_mut().enumerate() {
                    *v = 0.3 + 0.4 * (((i * (7919 + c * 13)) % 1013) as f32 / 1013.0);
                }
            }
            // Red clipped high in a blob and low along a row; green clipped high at
            // two pixels only (too rare for large frames); blue untouched.
            for y in h / 3..h / 2 {
                for x in w / 2..w.min(w / 2 + 11) {
                    img.channels[0][y * w + x] = 1.0;
                }
            }
            for x in 0..w / 3 {
                img.channels[0][(h - 1) * w + x] = 0.0;
            }
            img.channels[1][w + 1] = 1.0;
            img.channels[1][w * h - 1] = 1.0;
            let limits = clip_limits(&img);
            let (fused, masks) = blind_clip_masks(&img, 8);
            assert_eq!(fused, limits, "{w}×{h}");
            // Fed band by band as the blind fit's first reduce reads the rows: the
            // same tiles as read at once.
            for c in 0..3 {
                let (mut visited, mut at_once) = (TileExtremes::new(w, h, 8), TileExtremes::new(w, h, 8));
                crate::image::reduce_slice_visiting(&img.channels[c], w, h, |y| visited.rows_read(&img.channels[c], y));
                at_once.rows_read(&img.channels[c], h - 1);
                assert_eq!(visited, at_once, "{w}×{h} channel {c}");
            }
            for c in 0..3 {
                let reference = clip_mask_of(&img, &limits, 8, None, &[c]);
                for y in (0..h).step_by(3) {
                    for x in (0..w).step_by(3) {
                        for r in [0, 5, 13, 40] {
                            for coarse in [false, true] {
                                assert_eq!(
                                    masks[c].touches(x, y, r, coarse),
                                    reference.touches(x, y, r, coarse),
                                    "{w}×{h} channel {c} at ({x}, {y}) r {r}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// A reference that does not hold in a 2-px border and a 12-px square: the
    /// noise fit skips samples whose footprint holds more than 2% of such pixels
    /// and still recovers the noise (within 5%; 1.1% with a clean reference
    /// everywhere: the mask costs samples, not accuracy);
    /// the invalid pixels hold garbage (0.5 of a grey) that would ruin the fit if
    /// used.
    #[test]
    fn invalid_reference_pixels_are_skipped() {
        let (w, h) = (320, 240);
        // A luma ramp 0.2 … 0.8, so the per-luma map is identifiable.
        let mut clean = Rgb::new(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    clean.channels[c][y * w + x] = 0.2 + 0.6 * x as f32 / (w - 1) as f32;
                }
            }
        }
        let truth = crate::synth::white_sensor_noise([1e-4; 3], [4e-4; 3], [0.0, 1.0]);
        let noisy = crate::synth::add_noise(&clean, &truth, 3);
        let mut reference = clean.clone();
        let mut valid = Plane::new(w, h, 1.0);
        for y in 0..h {
            for x in 0..w {
                let border = x < 2 || y < 2 || x >= w - 2 || y >= h - 2;
                let square = (150..162).contains(&x) && (100..112).contains(&y);
                if border || square {
                    valid.data[y * w + x] = 0.0;
                    for c in 0..3 {
                        reference.channels[c][y * w + x] = 0.0;
                    }
                }
            }
        }
        let (fitted, _) = fit_accurate(&noisy, &reference, Some(&valid), &Default::default());
        assert!(fitted.present, "{}", fitted.diagnostics.reason);
        let e = crate::model::compare::noise_relative_error(&fitted, &truth).expect("present");
        assert!(e < 0.05, "median relative error {e}");
    }
}

mod leakage_tests {
    use super::super::*;

    /// Random grey tiles (16 px, 0.2 … 0.8, 1-px linear ramps between them)
    /// sampled at x + `dx`: the edges are what a misregistered reference leaves
    /// behind.
    fn tiles(w: usize, h: usize, dx: f32) -> Rgb {
        let tile = |tx: i64, ty: i64| {
            let v = crate::synth::gaussian(tx as u32, ty as u32, 0, 0x711e);
            0.5 + 0.3 * (v / 3.0).clamp(-1.0, 1.0)
        };
        let at = |x: f32, y: f32| {
            // Ramps, not steps: a sub-pixel shift then moves the edge by exactly dx.
            let (fx, fy) = (x / 16.0, y / 16.0);
            let (tx, ty) = (fx.floor() as i64, fy.floor() as i64);
            let (ux, uy) = (((fx - tx as f32) * 16.0).min(1.0), ((fy - ty as f32) * 16.0).min(1.0));
            let a = tile(tx - 1, ty - 1) * (1.0 - ux) + tile(tx, ty - 1) * ux;
            let b = tile(tx - 1, ty) * (1.0 - ux) + tile(tx, ty) * ux;
            a * (1.0 - uy) + b * uy
        };
        let mut img = Rgb::new(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = at(x as f32 + 32.0 + dx, y as f32 + 32.0);
                for c in 0..3 {
                    img.channels[c][y * w + x] = v;
                }
            }
        }
        img
    }

    /// A reference misregistered by 0.3 px leaves the tiles' edges in I − I_noNoise:
    /// least squares reads them as noise (+122% median error, measured with the
    /// leak test off), the median samples do not follow: the fit reports the leak,
    /// and where asked to refuse (`FitOptions::noise_min_leak_ratio`) says "not
    /// identifiable". A registered reference reports no leak and reads the noise
    /// within 3% (the fit's known answer on white noise; ~1% measured).
    #[test]
    fn a_misregistered_reference_is_reported_or_refused_a_registered_one_is_not() {
        let (w, h) = (320, 240);
        let clean = tiles(w, h, 0.0);
        let truth = crate::synth::white_sensor_noise([4e-5; 3], [1.6e-4; 3], [0.0, 1.0]);
        let noisy = crate::synth::add_noise(&clean, &truth, 5);
        let (registered, _) = fit_accurate(&noisy, &clean, None, &Default::default());
        assert!(registered.present, "{}", registered.diagnostics.reason);
        assert!(!registered.diagnostics.reason.contains("leak"), "{}", registered.diagnostics.reason);
        let e = crate::model::compare::noise_relative_error(&registered, &truth).expect("present");
        assert!(e < 0.03, "registered: median relative error {e}");

        let refuse = crate::fit::FitOptions { noise_min_leak_ratio: Some(MIN_LEAK_RATIO), ..Default::default() };
        let (kept, _) = fit_accurate(&noisy, &tiles(w, h, 0.3), None, &Default::default());
        assert!(kept.present && kept.diagnostics.reason.contains("leak"), "{}", kept.diagnostics.reason);
        let (fit, _) = fit_accurate(&noisy, &tiles(w, h, 0.3), None, &refuse);
        assert_eq!(fit.diagnostics.status, Status::NotIdentifiable, "{}", fit.diagnostics.reason);
        assert!(!fit.present);
        assert!(fit.diagnostics.reason.contains("image structure"), "{}", fit.diagnostics.reason);
    }
}

mod blocking_tests {
    use super::super::*;

    /// The grid detector alone (`compression_blocking`, which the worker calls on
    /// any frame it is given) answers "no grid" on frames too small to hold one —
    /// 1×1, 7×5, 31×31 — and on a flat or non-finite frame, without a panic; an
    /// 8-px grid of 0.03 steps on a 64×64 noise frame is found at its phase.
    #[test]
    fn grid_detection_at_the_extremes() {
        for (w, h) in [(1usize, 1usize), (7, 5), (31, 31)] {
            assert!(compression_blocking(&Rgb::new(w, h, [0.5; 3])).is_none(), "{w}×{h}");
        }
        assert!(compression_blocking(&Rgb::new(64, 64, [0.5; 3])).is_none(), "flat");
        assert!(compression_blocking(&Rgb::new(64, 64, [f32::NAN; 3])).is_none(), "NaN");
        // Noise plus a constant offset per 8×8 block starting at column/row 3.
        let mut img = Rgb::new(64, 64, [0.5; 3]);
        for y in 0..64 {
            for x in 0..64 {
                let n = 0.3 * crate::synth::gaussian(x as u32, y as u32, 0, 12345);
                let block = ((x + 5) / 8 + 3 * ((y + 5) / 8)) % 4;
                for c in 0..3 {
                    img.channels[c][y * 64 + x] = 0.5 + 0.01 * n + 0.03 * block as f32;
                }
            }
        }
        let b = compression_blocking(&img).expect("the grid");
        assert_eq!(b.period_px, 8);
        assert_eq!(b.phase_px, [2, 2], "{b:?}");
    }
}

mod texture_floor_tests {
    use super::super::blind::texture_bias;

    /// The frame-alone fit's texture-floor bias: 1 (the noise could be half the
    /// reading or less) at and below the floor and for readings that are not a
    /// positive number; falling with the reading above it, toward √(1 + k²) − 1 (the
    /// selection's share, 3.3%) for strong noise; finite and in [0, 1] at every
    /// extreme. The middle values are the model's own (0.006 in level-0 std, k 0.26),
    /// to rounding (1e-4).
    #[test]
    fn texture_bias_is_bounded_and_falls_with_the_reading() {
        for s in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, 0.0, 1e-30, 0.003, 0.006, 0.0069] {
            assert_eq!(texture_bias(s), 1.0, "reading {s}");
        }
        let floor_share = (1.0f64 + 0.26f64.powi(2)).sqrt() - 1.0;
        for s in [1e3f32, 1e30, f32::MAX] {
            let b = texture_bias(s) as f64;
            assert!((b - floor_share).abs() < 1e-4, "reading {s}: {b} against {floor_share}");
        }
        // At 0.012 (twice the floor): 0.012 / √((0.012² − 0.006²) / 1.0676) − 1.
        let want = 0.012f64 / ((0.012f64.powi(2) - 0.006f64.powi(2)) / (1.0 + 0.26f64.powi(2))).sqrt() - 1.0;
        assert!((texture_bias(0.012) as f64 - want).abs() < 1e-4, "{} against {want}", texture_bias(0.012));
        let mut last = 1.0f32;
        for i in 0..2000 {
            let s = 0.0069 + i as f32 * 1e-4;
            let b = texture_bias(s);
            assert!(b.is_finite() && (0.0..=1.0).contains(&b) && b <= last, "reading {s}: {b} after {last}");
            last = b;
        }
    }
}

mod raster_order_tests {
    use super::super::blind::map_in_raster_order;

    /// The flat samples' window values: `f` called once per sample, in raster order
    /// (rows, then columns), and each value written to its sample's own slot, so the
    /// vector is the one `pts.iter().map(f)` makes — the medians and sums taken of it
    /// after are the same bit for bit. Scrambled positions on a grid, a single sample
    /// and none.
    #[test]
    fn values_land_in_their_slots_and_are_computed_in_raster_order() {
        let samples: Vec<(usize, usize, f32, f32, u8)> = (0..97usize)
            .map(|i| {
                let k = (i * 37) % 97; // a permutation of 0..97
                (3 + 11 * (k % 9), 5 + 11 * (k / 9), k as f32, -(k as f32), 7)
            })
            .collect();
        let value = |p: &(usize, usize, f32, f32, u8)| (p.0 * 1000 + p.1) as f32 + 0.25;
        for n in [0usize, 1, 97] {
            let pts: Vec<&(usize, usize, f32, f32, u8)> = samples[..n].iter().collect();
            let mut calls = vec![];
            let got = map_in_raster_order(&pts, |p| {
                calls.push((p.1, p.0));
                value(p)
            });
            let want: Vec<f32> = pts.iter().map(|p| value(p)).collect();
            assert_eq!(
                got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
            assert_eq!(calls.len(), n);
            assert!(calls.windows(2).all(|w| w[0] < w[1]), "not in raster order: {calls:?}");
        }
    }

    /// `sorted_stably_by` orders as the stable `sort_by(total_cmp)` does, ties in
    /// their given order: many equal keys, ±0, subnormals, ±∞ and NaNs of both
    /// signs, none and one item.
    #[test]
    fn packed_keys_sort_as_the_stable_total_order() {
        use super::super::blind::sorted_stably_by;
        let specials =
            [0.0f32, -0.0, 1e-40, -1e-40, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, 1.0, -1.0, f32::MAX];
        let keys: Vec<f32> = (0..300usize)
            .map(|i| if i % 7 == 0 { specials[i % specials.len()] } else { ((i * 37) % 13) as f32 * 0.5 - 3.0 })
            .collect();
        let items: Vec<(usize, f32)> = keys.iter().copied().enumerate().collect();
        for n in [0usize, 1, 2, 300] {
            let refs: Vec<&(usize, f32)> = items[..n].iter().collect();
            let mut want = refs.clone();
            want.sort_by(|a, b| a.1.total_cmp(&b.1));
            let got = sorted_stably_by(&refs, |t| t.1);
            assert_eq!(
                got.iter().map(|t| t.0).collect::<Vec<_>>(),
                want.iter().map(|t| t.0).collect::<Vec<_>>(),
                "{n}"
            );
        }
    }
}

mod measured_tables_tests {
    use super::super::*;
    use crate::synth::measured_check::{check, Table};

    /// The stored white-noise tables of the fits equal a fresh measurement
    /// (tolerance in `measured_check::check`).
    #[test]
    fn measured_tables_fit_noise() {
        let m2m = measure_white_noise_median_to_mean();
        let bicubic = blind::measure_bicubic_noise_transmission();
        let as_f64 = |v: &[f32]| -> Vec<f64> { v.iter().map(|&x| x as f64).collect() };
        check(
            "src/fit/noise/measured.rs",
            "White-noise tables of the noise fits, measured once.",
            &[
                Table {
                    name: "WHITE_NOISE_MEDIAN_TO_MEAN",
                    ty: "[f32; crate::model::NOISE_LEVELS]",
                    doc: "/// `measure_white_noise_median_to_mean`: median / mean of white noise's local band variances.",
                    stored: as_f64(&measured::WHITE_NOISE_MEDIAN_TO_MEAN),
                    fresh: as_f64(&m2m),
                    literal: format!("{m2m:?}"),
                },
                Table {
                    name: "BICUBIC_NOISE_TRANSMISSION",
                    ty: "[f32; crate::model::NOISE_LEVELS]",
                    doc: "/// `blind::measure_bicubic_noise_transmission`: band variance kept by a bicubic sub-pixel shift.",
                    stored: as_f64(&measured::BICUBIC_NOISE_TRANSMISSION),
                    fresh: as_f64(&bicubic),
                    literal: format!("{bicubic:?}"),
                },
            ],
        );
    }
}

mod status_tests {
    use super::super::*;

    /// One level-0 map of std `std` (linear-std form, flat in luma) with a variance
    /// standard error of `var_se`, and three bins of samples.
    fn finished(std: f64, var_se: f64) -> Noise {
        let level = NoiseLevel { slope: [0.0; 3], intercept: [std as f32; 3] };
        let cov = [[var_se * var_se, 0.0], [0.0, 0.0]];
        let fit = LevelFit {
            form: NoiseForm::LinearStd,
            intensity: NoiseIntensity::Luma,
            levels: vec![level; NOISE_LEVELS],
            covs: vec![[cov; 3]; NOISE_LEVELS],
            rel_res: 0.01,
            nll: 0.0,
        };
        let v = (std * std) as f32;
        let samples = vec![LevelSamples {
            y: vec![0.3, 0.5, 0.7],
            y2: vec![0.09, 0.25, 0.49],
            own: None,
            var: [vec![v; 3], vec![v; 3], vec![v; 3]],
        }];
        finish("fast", Instant::now(), Some(fit), &samples, [0.3, 0.7], false)
    }

    /// A level-0 std pinned down is present; one of 1/1000 whose standard error
    /// spans zero is not identifiable — never absent (a real in-camera JPEG shot
    /// read that way: `cargo xtask bench-quality`'s real camera noise); one below
    /// 1e-4 is absent whatever its error.
    #[test]
    fn an_uncertain_reading_is_not_identifiable_and_an_invisible_one_absent() {
        let s = 4e-3;
        let sure = finished(s, 0.05 * s * s);
        assert_eq!(sure.diagnostics.status, Status::Present, "{}", sure.diagnostics.reason);
        assert!(sure.present);
        let unsure = finished(s, 2.0 * s * s);
        assert_eq!(unsure.diagnostics.status, Status::NotIdentifiable, "{}", unsure.diagnostics.reason);
        assert!(!unsure.present);
        let invisible = finished(5e-5, 2.0 * 5e-5 * 5e-5);
        assert_eq!(invisible.diagnostics.status, Status::Absent, "{}", invisible.diagnostics.reason);
        assert!(!invisible.present);
    }
}
