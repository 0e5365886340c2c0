//! The plane-to-image homography (normalised DLT) and the plane pose it implies, shared by the
//! intrinsics bootstrap (`solve::intrinsics`), the ChArUco corner completion (`vision::charuco`)
//! and the board pose's start (`vision::pnp`). Depends on nothing else of ours but `geometry`.

use nalgebra::{Matrix3, Point2, SMatrix, Translation3, Vector3};

use super::{project_to_rotation, Pose};

/// The homography from plane points (a board's `x`, `y`, any unit) to pixels, by the DLT with
/// Hartley normalisation of both point sets, scaled so `H[(2, 2)] = 1` where it is not near
/// zero; `None` with fewer than 4 points, unequal counts or a degenerate point set.
pub fn homography(plane: &[(f64, f64)], pixels: &[Point2<f64>]) -> Option<Matrix3<f64>> {
    let n = plane.len();
    if n < 4 || pixels.len() != n {
        return None;
    }
    // Hartley normalisation of both point sets.
    let normaliser = |pts: &mut dyn Iterator<Item = (f64, f64)>| {
        let v: Vec<(f64, f64)> = pts.collect();
        let (mx, my) = v.iter().fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
        let (mx, my) = (mx / n as f64, my / n as f64);
        let d = v
            .iter()
            .map(|p| ((p.0 - mx).powi(2) + (p.1 - my).powi(2)).sqrt())
            .sum::<f64>()
            / n as f64;
        let s = if d > 0.0 {
            std::f64::consts::SQRT_2 / d
        } else {
            1.0
        };
        Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
    };
    let tp = normaliser(&mut plane.iter().copied());
    let ti = normaliser(&mut pixels.iter().map(|p| (p.x, p.y)));
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (q, p) in plane.iter().zip(pixels) {
        let a = tp * Vector3::new(q.0, q.1, 1.0);
        let b = ti * Vector3::new(p.x, p.y, 1.0);
        let (x, y, u, v) = (a.x, a.y, b.x, b.y);
        let r1 =
            SMatrix::<f64, 1, 9>::from_row_slice(&[-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u]);
        let r2 =
            SMatrix::<f64, 1, 9>::from_row_slice(&[0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v]);
        ata += r1.transpose() * r1 + r2.transpose() * r2;
    }
    let eigen = ata.symmetric_eigen();
    let (k, _) = eigen
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = eigen.eigenvectors.column(k);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let hm = ti.try_inverse()? * hn * tp;
    let scale = hm[(2, 2)];
    let hm = if scale.abs() > 1e-12 { hm / scale } else { hm };
    hm.iter().all(|v| v.is_finite()).then_some(hm)
}

/// The plane's pose `T_camera_plane` that a plane-to-pixel homography `h` implies for a pinhole
/// camera matrix `k` (the identity when the pixels are normalised image points), the plane in
/// front of the camera; `None` when it gives no usable rotation.
pub fn pose_from_homography(h: &Matrix3<f64>, k: &Matrix3<f64>) -> Option<Pose> {
    let m = k.try_inverse()? * h;
    let (c1, c2, c3) = (
        m.column(0).into_owned(),
        m.column(1).into_owned(),
        m.column(2).into_owned(),
    );
    let mut lambda = 2.0 / (c1.norm() + c2.norm());
    // The plane is in front of the camera.
    if c3.z * lambda < 0.0 {
        lambda = -lambda;
    }
    let (r1, r2, t) = (c1 * lambda, c2 * lambda, c3 * lambda);
    if !t.iter().all(|v| v.is_finite()) {
        return None;
    }
    let rotation = project_to_rotation(&Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]))?;
    Some(Pose::from_parts(Translation3::from(t), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_maps_plane_points_to_their_pixels() {
        let h_true = Matrix3::new(700.0, 30.0, 600.0, -20.0, 650.0, 300.0, 0.1, -0.2, 1.0);
        let plane: Vec<(f64, f64)> = (0..5)
            .flat_map(|i| (0..4).map(move |j| (0.05 * i as f64, 0.05 * j as f64)))
            .collect();
        let pixels: Vec<Point2<f64>> = plane
            .iter()
            .map(|&(x, y)| {
                let p = h_true * Vector3::new(x, y, 1.0);
                Point2::new(p.x / p.z, p.y / p.z)
            })
            .collect();
        let h = homography(&plane, &pixels).unwrap();
        for (q, p) in plane.iter().zip(&pixels) {
            let m = h * Vector3::new(q.0, q.1, 1.0);
            // Exact data: the DLT reproduces every pixel to numerical precision.
            assert!((Point2::new(m.x / m.z, m.y / m.z) - p).norm() < 1e-8);
        }
        assert!(homography(&plane[..3], &pixels[..3]).is_none());
    }
}
