//! Benchmark `animate`: one frame of an animated scene, `Animator::frame`, at several block
//! budgets.
//!
//! Run with `cargo bench -p render --bench animate`. Before the benchmarks it prints, per
//! budget, the depth the pulsing ball got and the blocks evaluated.
//!
//! The scene: a ball whose radius pulses with time (`0.6 + 0.2 sin(2t) - |p|`, a shape of
//! time, meshed again every frame), a ball whose colour cycles (a look of time, coloured again),
//! a box sliding along x (a motion, placed again), and the thesis's whirlpool cylinder with
//! its force field (Figure 7.4: 7 arrows along its longest side, sampled again every frame).
//! Each benchmark iteration is one frame, 1/30 s after the previous one.

use divan::Bencher;
use render::animation::{Animator, FrameBudget};
use render::snapshot::SnapshotSettings;

/// Block budgets per frame: about depth 5, 6 and 7 of the pulsing ball.
const BUDGETS: [usize; 3] = [60, 400, 2500];

fn main() {
    print_depths();
    divan::main();
}

fn scene() -> model::scene::Scene {
    let text = concat!(
        r#"
        DEF Pulse FShape { geometry FGeometry {
            definition "0.6+0.2*sin(2*t)-sqrt(x^2+y^2+z^2)" bboxSize 1.8 1.8 1.8 } }
        DEF Blush FShape {
            geometry FGeometry { definition "0.3-sqrt((x-2)^2+y^2+z^2)"
                bboxCenter 2 0 0 bboxSize 0.8 0.8 0.8 }
            appearance FAppearance { material FMaterial {
                diffuseColor "r = 0.5+0.5*sin(t); g = 0.2; b = 0.5-0.5*sin(t);" } } }
        FTransform { translationFunction "x = -2+0.5*sin(t); y = 0; z = 0;" children [
            DEF Slide FShape { geometry Box { size 0.4 0.4 0.4 } } ] }
        Transform { translation 0 -2 0 children [
        "#,
        include_str!("../../tests/data/scenes/figure_7_4.wrl"),
        "] }"
    );
    let mut no_files = |path: &str| Err(format!("no file {path}"));
    formats::fvrml::load(text, &formats::fvrml::LoadOptions::default(), &mut no_files)
        .expect("the scene loads")
        .scene
}

fn settings() -> SnapshotSettings {
    SnapshotSettings {
        depth: 8,
        ..SnapshotSettings::default()
    }
}

#[divan::bench(args = BUDGETS, sample_count = 20, sample_size = 1)]
fn frame(bencher: Bencher, blocks_max: usize) {
    let mut animator = Animator::new(&scene(), &settings()).expect("valid settings");
    let budget = FrameBudget { blocks_max };
    let mut k = 0u32;
    bencher.bench_local(|| {
        k += 1;
        animator.frame(f64::from(k) / 30.0, budget).blocks_evaluated
    });
}

fn print_depths() {
    // Under `cargo test` benches run once as tests: skip the table there.
    if std::env::args().any(|a| a == "--test") {
        return;
    }
    let mut animator = Animator::new(&scene(), &settings()).expect("valid settings");
    for blocks_max in BUDGETS {
        let stats = animator.frame(1.0, FrameBudget { blocks_max });
        println!(
            "budget {blocks_max:5} blocks: pulsing ball at depth {}, {} blocks evaluated, over budget: {}, {} recoloured, {} moved, {} lines",
            stats.remeshed.first().map_or(0, |r| r.1),
            stats.blocks_evaluated,
            stats.over_budget,
            stats.n_recoloured,
            stats.n_moved,
            animator.scene().lines.len()
        );
    }
}
