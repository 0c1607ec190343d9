//! `Plane::sample_line` against its previous form (chunks of a run-time length up
//! to 32 lanes), per line, at the lengths the blind exposure reads: 9 and 17 nodes
//! (the isotropy profiles at 8 px/frame, half and full scale), 33 and 65 (faster
//! flows, the streak lines). Lines on a 1280×960 plane in raster order, 16 384 per
//! round, each form's fastest of 300 interleaved rounds (this VM's speed drifts
//! within a minute), every node checked bit for bit against the library's.
//!
//! `cargo run --release --example line_bench` (`RAND=1`: lines at scattered
//! positions, cache misses included).
use blind_augment::image::Plane;
use std::time::Instant;

/// The previous `sample_line` interior path: chunks of up to 32 nodes, each in
/// three loops over a run-time length (zeroed scratch arrays, loops not unrolled).
#[inline(never)]
fn runtime_chunks(p: &Plane, x0: f32, y0: f32, dx: f32, dy: f32, out: &mut [f32]) {
    const CHUNK: usize = 32;
    const TWO_23: f32 = 8_388_608.0;
    let floor_inside = |v: f32| {
        let r = (v + TWO_23) - TWO_23;
        r - if r > v { 1.0 } else { 0.0 }
    };
    let w = p.width;
    let wf = w as f32;
    for (c, chunk) in out.chunks_mut(CHUNK).enumerate() {
        let n = chunk.len();
        let (mut fx, mut fy, mut at) = ([0.0f32; CHUNK], [0.0f32; CHUNK], [0u32; CHUNK]);
        for k in 0..n {
            let j = (c * CHUNK + k) as f32;
            let (x, y) = (x0 + j * dx, y0 + j * dy);
            let (xf, yf) = (floor_inside(x), floor_inside(y));
            fx[k] = x - xf;
            fy[k] = y - yf;
            at[k] = (yf * wf + xf + TWO_23).to_bits() - TWO_23.to_bits();
        }
        let (mut a, mut b, mut cc, mut d) = ([0.0f32; CHUNK], [0.0f32; CHUNK], [0.0f32; CHUNK], [0.0f32; CHUNK]);
        for k in 0..n {
            let i = at[k] as usize;
            let q = &p.data[i..i + w + 2];
            (a[k], b[k], cc[k], d[k]) = (q[0], q[1], q[w], q[w + 1]);
        }
        for k in 0..n {
            let top = a[k] + (b[k] - a[k]) * fx[k];
            let bottom = cc[k] + (d[k] - cc[k]) * fx[k];
            chunk[k] = top + (bottom - top) * fy[k];
        }
    }
}

fn main() {
    let (w, h) = (1280usize, 960usize);
    let data: Vec<f32> = (0..w * h).map(|i| (i.wrapping_mul(2_654_435_761) % 1000) as f32 / 1000.0).collect();
    let p = Plane::from_vec(w, h, data);
    let scattered = std::env::var("RAND").is_ok();
    const LINES: usize = 16_384;
    // Line s: its start (raster order, 30 px apart in rows 6 px apart, or scattered)
    // and a direction of varying slope; every one ends inside the plane.
    let line = |s: usize| -> (f32, f32, f32, f32) {
        let (x, y) = if scattered {
            let r = s.wrapping_mul(2_654_435_761) % (1200 * 900);
            (20.0 + (r % 1200) as f32, 20.0 + (r / 1200) as f32)
        } else {
            (20.0 + ((s * 30) % 1200) as f32, 20.0 + ((s * 30 / 1200) * 6 % 900) as f32)
        };
        (x + 0.3 + (s % 3) as f32 * 0.137, y + 0.7, 0.1 + (s % 11) as f32 * 0.031, 0.45)
    };
    println!("nodes | previous (run-time chunks) | sample_line | ratio");
    for n in [9usize, 17, 33, 65] {
        let (mut out, mut want) = (vec![0.0f32; n], vec![0.0f32; n]);
        for s in 0..LINES {
            let (x, y, dx, dy) = line(s);
            runtime_chunks(&p, x, y, dx, dy, &mut want);
            p.sample_line(x, y, dx, dy, &mut out);
            assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "line {s}, {n} nodes differ");
        }
        let mut best = [f64::MAX; 2];
        let mut sink = 0.0f32;
        for _ in 0..300 {
            for (form, b) in best.iter_mut().enumerate() {
                let t = Instant::now();
                for s in 0..LINES {
                    let (x, y, dx, dy) = line(s);
                    if form == 0 {
                        runtime_chunks(&p, x, y, dx, dy, &mut out);
                    } else {
                        p.sample_line(x, y, dx, dy, &mut out);
                    }
                    sink += out[n / 2];
                }
                *b = b.min(t.elapsed().as_secs_f64());
            }
        }
        let ns = |t: f64| t * 1e9 / LINES as f64;
        println!("{n} | {:.1} ns | {:.1} ns | {:.2} (sink {sink:.0})", ns(best[0]), ns(best[1]), best[1] / best[0]);
    }
}
