//! The Rust side of the Python call-overhead figure (issue #28): `handeye_solve::solve` with the
//! options `handeye.calibrate` uses by default (the CLI's: refined, noise estimated, outliers
//! dropped) on the N = 20 data set `bench/overhead.py` times from Python
//! (`bench/n20.yaml`, written by `python bench/overhead.py --write-dataset`; another file with
//! `HANDEYE_BENCH_DATASET`). Compare its time with the script's `timeit` of `handeye.calibrate`
//! on the same samples: the figures are in docs/python.md.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use handeye_records::dataset::Dataset;
use handeye_solve::{NoiseModel, SolveOptions};

fn bench(c: &mut Criterion) {
    let path = std::env::var_os("HANDEYE_BENCH_DATASET")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench/n20.yaml"));
    let dataset = Dataset::load(&path).expect("the bench data set reads");
    let (noise, estimate_noise) = NoiseModel::given_or_estimated(None, None, true);
    let options = SolveOptions {
        noise,
        estimate_noise,
        drop_outliers: true,
        ..SolveOptions::default()
    };
    let name = format!("solve/default/N={}", dataset.pairs.len());
    c.bench_function(&name, |b| {
        b.iter(|| {
            handeye_solve::solve(dataset.setup, black_box(&dataset.pairs), &options)
                .expect("the bench data set solves")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(3))
        .sample_size(30);
    targets = bench
}
criterion_main!(benches);
