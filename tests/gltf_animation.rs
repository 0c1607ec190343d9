//! Skins and morph targets of glTF files made elsewhere (Khronos sample models,
//! vendored from assimp's test set, CC0): the deformed vertices against the
//! values the glTF 2.0 spec's formulas give for the files' own data, worked out
//! here by hand, and the G-buffer's motion vectors of a skinned mesh against a CPU
//! projection of the same surface points one render frame apart.

mod common;

use blind_augment::gpu::FrameRing;
use blind_augment::render::gbuffer::{clip_from_view, FAR_M, NEAR_M};
use blind_augment::render::{Eye, GBufferFrame, GBufferPass};
use blind_augment::scene::Scene;
use glam::{Mat4, Vec3};
use std::path::PathBuf;

fn sample(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/gltf_samples").join(rel)
}

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tol)
}

/// SimpleSkin: a 1 × 2 m strip of 10 vertices, two joints at (0, 1, 0), both
/// inverse bind matrices a translation by (−0.5, −1, 0); the second joint turns
/// about z to +90° at t = 1 s (keyframe (0, 0, 0.707, 0.707)). Linear blend
/// skinning (glTF 2.0 §3.7.3.3) then puts, by hand:
/// vertex 0 (0, 0, 0), all on joint 0 → (−0.5, 0, 0) at any time;
/// vertex 9 (1, 2, 0), all on joint 1 → (0, 1, 0) + R₉₀·(0.5, 1, 0) = (−1, 1.5, 0);
/// vertex 4 (0, 1, 0), half on each → ½(−0.5, 1, 0) + ½((0, 1, 0) + R₉₀·(−0.5, 0, 0))
/// = (−0.25, 0.75, 0). Tolerance 1e-5 m: f32 arithmetic on unit-sized values.
#[test]
fn simple_skin_follows_its_joints() {
    let scene = Scene::load(&sample("SimpleSkin/simple_skin.gltf")).expect("SimpleSkin loads");
    assert_eq!(scene.skins.len(), 1);
    assert!(!scene.notes.iter().any(|n| n.contains("skin")), "notes: {:?}", scene.notes);
    let at = |t: f64| scene.pose_at(t, Mat4::IDENTITY).deformed[0].clone().expect("the skinned mesh deforms");
    let rest = at(0.0);
    assert!(close(rest[0].position, [-0.5, 0.0, 0.0], 1e-5), "{:?}", rest[0].position);
    assert!(close(rest[9].position, [0.5, 2.0, 0.0], 1e-5), "{:?}", rest[9].position);
    let bent = at(1.0);
    assert!(close(bent[0].position, [-0.5, 0.0, 0.0], 1e-5), "{:?}", bent[0].position);
    assert!(close(bent[9].position, [-1.0, 1.5, 0.0], 1e-5), "{:?}", bent[9].position);
    assert!(close(bent[4].position, [-0.25, 0.75, 0.0], 1e-5), "{:?}", bent[4].position);
    // The work rectangle follows the bent strip, not the bind pose's bounds.
    let corners = scene.world_corners(1.0, Mat4::IDENTITY);
    let min_x = corners.iter().map(|c| c.x).fold(f32::MAX, f32::min);
    assert!((min_x + 1.0).abs() < 1e-5, "bounds' min x {min_x}, the bent strip reaches −1");
    // The skinned mesh's node transform is ignored (§3.7.3.3): placing the scene
    // moves it through the joints alone.
    let placed = scene.pose_at(1.0, Mat4::from_translation(Vec3::new(0.0, 0.0, -2.0)));
    let v = placed.deformed[0].as_ref().expect("deformed")[9].position;
    assert!(close(v, [-1.0, 1.5, -2.0], 1e-5), "{v:?}");
    assert_eq!(placed.world_from_object[0], Mat4::IDENTITY);
}

/// SimpleMorph: a triangle whose vertex 2 (0.5, 0.5, 0) has displacements
/// (−1, 1, 0) and (1, 1, 0) in its two targets; the weights animation's keys are
/// (0, 0), (0, 1), (1, 1), (1, 0), (0, 0) at t = 0…4 s, LINEAR (the mesh's default
/// weights 0.5, 0.5 are overridden). At 1.5 s the weights are (0.5, 1): vertex 2 at
/// (0.5 − 0.5 + 1, 0.5 + 0.5 + 1, 0) = (1, 2, 0); at 3.5 s (0.5, 0): (0, 1, 0).
#[test]
fn simple_morph_follows_its_weights() {
    let scene = Scene::load(&sample("SimpleMorph/SimpleMorph.gltf")).expect("SimpleMorph loads");
    assert_eq!(scene.weight_channels.len(), 1);
    assert!((scene.duration_s - 4.0).abs() < 1e-6, "duration {}", scene.duration_s);
    let at = |t: f64| scene.pose_at(t, Mat4::IDENTITY).deformed[0].clone().expect("the morphed mesh deforms");
    assert!(close(at(1.5)[2].position, [1.0, 2.0, 0.0], 1e-5), "{:?}", at(1.5)[2].position);
    assert!(close(at(3.5)[2].position, [0.0, 1.0, 0.0], 1e-5), "{:?}", at(3.5)[2].position);
    assert!(close(at(0.0)[2].position, [0.5, 0.5, 0.0], 1e-5), "{:?}", at(0.0)[2].position);
    // Vertices without displacement stay.
    assert!(close(at(2.0)[0].position, [0.0, 0.0, 0.0], 1e-6));
}

/// AnimatedMorphCube (two targets with normal displacements, weights animated):
/// the shape changes over the loop, every vertex and normal stays finite and
/// unit, and the bounds the renderer's work rectangle uses follow the shape.
#[test]
fn animated_morph_cube_changes_shape_with_unit_normals() {
    let scene = Scene::load(&sample("AnimatedMorphCube/AnimatedMorphCube.gltf")).expect("AnimatedMorphCube loads");
    assert!(scene.duration_s > 0.0);
    let steps = 24;
    let mut extents = Vec::new();
    for k in 0..steps {
        let t = scene.duration_s as f64 * k as f64 / steps as f64;
        let pose = scene.pose_at(t, Mat4::IDENTITY);
        assert!(pose.is_finite(), "t = {t}");
        let v = pose.deformed[0].as_ref().expect("deforms");
        for x in v.iter() {
            let n = Vec3::from(x.normal).length();
            assert!((n - 1.0).abs() < 1e-4, "t = {t}: normal length {n}");
        }
        let c = pose.world_corners(&scene);
        let (lo, hi) =
            c.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(a, b), p| (a.min(*p), b.max(*p)));
        extents.push((hi - lo).length());
    }
    let (lo, hi) = extents.iter().fold((f32::MAX, f32::MIN), |(a, b), &e| (a.min(e), b.max(e)));
    assert!(hi > lo * 1.05, "the morph changes the cube's extent over the loop: {extents:?}");
}

const W: u32 = 160;
const H: u32 = 120;
const F: f32 = 150.0;

fn project(e: &Eye, p: Vec3) -> (f32, f32) {
    let c = clip_from_view(e.focal_px, e.centre_px, W, H, NEAR_M, FAR_M) * e.view_from_world * p.extend(1.0);
    ((c.x / c.w + 1.0) * 0.5 * W as f32, (c.y / c.w + 1.0) * 0.5 * H as f32)
}

/// A waving skinned strip streaks: with the head still, the G-buffer's motion at
/// each triangle's centroid equals the centroid's projection now minus its
/// projection one render frame (1/45 s) earlier, both from the CPU's skinning.
/// Joint 1 turns at ~1.6 rad/s near t = 0.25 s, so the upper triangles move ~1–3
/// px per frame and the lower ones (on the still joint 0) hardly at all. Tolerance
/// 0.1 px: the nearest pixel centre is ≤ 0.71 px from the centroid and the motion
/// field's gradient there is ~0.04 px/px; f16 storage adds < 0.002 px.
#[test]
fn skinned_motion_vectors_follow_the_joints() {
    let Some(ctx) = common::gpu_context("skinned_motion_vectors_follow_the_joints") else { return };
    let scene = Scene::load(&sample("SimpleSkin/simple_skin.gltf")).expect("SimpleSkin loads");
    let pass = GBufferPass::new(&ctx, &scene, W, H, 2).expect("pass");
    let mut ring = FrameRing::new(&ctx, 2, 256).expect("ring");
    let eye = |x_m: f32| Eye {
        focal_px: F,
        centre_px: [W as f32 / 2.0, H as f32 / 2.0],
        view_from_world: Mat4::from_translation(Vec3::new(x_m, 1.0, 3.0)).inverse(),
    };
    let eyes = [eye(-0.032), eye(0.032)];
    let (t, dt) = (0.25f64, 1.0 / 45.0);
    let frame = GBufferFrame {
        eyes,
        prev_eyes: eyes,
        pose: scene.pose_at(t, Mat4::IDENTITY),
        prev_pose: scene.pose_at(t - dt, Mat4::IDENTITY),
        light_dir: Vec3::new(0.3, 1.0, 0.5),
        ambient: 0.3,
    };
    let (slot, cmd) = ring.begin().expect("begin");
    pass.record(cmd, slot, &frame).expect("record");
    ring.submit(slot).expect("submit");
    ring.wait_all().expect("wait");
    let motion: Vec<f32> = pass
        .motion()
        .download()
        .expect("motion")
        .chunks_exact(2)
        .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
        .collect();
    let now = frame.pose.deformed[0].as_ref().expect("deformed now");
    let before = frame.prev_pose.deformed[0].as_ref().expect("deformed before");
    let tris = &scene.meshes[0].indices;
    let n = (W * H) as usize;
    let (mut largest, mut checked) = (0.0f32, 0);
    for (layer, e) in eyes.iter().enumerate() {
        for tri in tris.chunks_exact(3) {
            let centroid = |v: &[blind_augment::scene::Vertex]| {
                tri.iter().map(|&i| Vec3::from(v[i as usize].position)).sum::<Vec3>() / 3.0
            };
            let (x, y) = project(e, centroid(now));
            let (px, py) = project(e, centroid(before));
            let (ix, iy) = (x.floor() as usize, y.floor() as usize);
            let at = 4 * (layer * n + iy * W as usize + ix);
            assert_eq!(motion[at + 3], 1.0, "eye {layer}: triangle {tri:?} not drawn at ({ix}, {iy})");
            let (mx, my) = (motion[at], motion[at + 1]);
            let (ex, ey) = (x - px, y - py);
            assert!(
                (mx - ex).abs() < 0.1 && (my - ey).abs() < 0.1,
                "eye {layer}, triangle {tri:?}: motion ({mx:.3}, {my:.3}) px, the joints give ({ex:.3}, {ey:.3})"
            );
            largest = largest.max(ex.hypot(ey));
            checked += 1;
        }
    }
    assert!(largest > 1.0, "the strip waves by {largest} px per frame: too little to tell skinning from none");
    assert_eq!(checked, 16);
    let msgs = ctx.take_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}
