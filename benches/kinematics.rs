//! Speed of the UR kinematics that plan checking and the simulated arm call per pose:
//! forward kinematics, all inverse solutions, and the nearest solution to a seed.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use handeye_robot::kinematics::UrModel;
use handeye_robot::Joints;

fn kinematics(c: &mut Criterion) {
    let model = UrModel::ur5e();
    let q = Joints::from([0.3, -1.2, 1.4, -0.8, 1.1, 0.4]);
    let pose = model.forward(&q);
    c.bench_function("ur5e forward", |b| b.iter(|| model.forward(black_box(&q))));
    c.bench_function("ur5e inverse (all 8)", |b| {
        b.iter(|| model.inverse(black_box(&pose)))
    });
    c.bench_function("ur5e inverse_nearest", |b| {
        b.iter(|| model.inverse_nearest(black_box(&pose), black_box(&q)))
    });
}

criterion_group!(benches, kinematics);
criterion_main!(benches);
