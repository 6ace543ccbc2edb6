//! Same input and options → bit-identical features, model parameters, corrected features
//! and images, lattice indices and unit cells, whatever the number of rayon threads.

use dhct_bench::determinism::{fingerprint, with_threads};
use dhct_bench::robustness::{MaskKind, base, mask};
use dhct_bench::scenario::pipeline_options;
use dhct_simulate::Simulation;

#[test]
fn outputs_are_bit_identical_across_thread_counts() {
    let config = base(256);
    let output = Simulation::from_config(&config).unwrap().run().unwrap();
    // The simulation itself is deterministic too: run it again in one thread.
    let again = with_threads(1, || {
        Simulation::from_config(&config).unwrap().run().unwrap()
    });
    assert!(
        again.pair == output.pair,
        "the simulation depends on the thread count"
    );

    let lattice = config.surface.lattice.build().unwrap();
    let options = pipeline_options(lattice.as_ref());
    let geometry = output.pair.geometry();
    let holes = mask(MaskKind::ManyHoles, geometry.rows(), geometry.columns());
    for (name, mask) in [("no mask", None), ("five holes", holes.as_ref())] {
        let run = |threads| {
            with_threads(threads, || {
                let analysis =
                    dhct_pipeline::run(&output.pair, lattice.as_ref(), mask, &options, &|_| {})
                        .expect("the chain runs");
                fingerprint(&analysis)
            })
        };
        let one = run(1);
        assert!(one.feature_count > 300, "{name}: {one:?}");
        assert!(
            one.unit_cell != 0,
            "{name}: the unit cell is part of the check"
        );
        for threads in [2, 3, 1] {
            let other = run(threads);
            assert_eq!(one, other, "{name}: 1 thread vs {threads} threads");
        }
        println!("{name}: {one:?} identical with 1, 2 and 3 threads");
    }
}
