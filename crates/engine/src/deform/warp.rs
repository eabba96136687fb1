//! How the head's outputs move one canonical Gaussian, and the chain rule back; f64 reference of
//! `deform/shaders/deform_apply_*.wgsl` (same formulas, same small-angle series).
//!
//! - position: `x + dx`, or the screw motion `exp([w, v]) x = R(w) x + V(w) v`;
//! - rotation: `normalize(q) + dq` (the released code adds the delta to the normalised quaternion;
//!   the rasteriser normalises the sum);
//! - scale: `log_s + ds`. The released code adds `ds` to the activated scale, which can turn a
//!   scale negative; in log space every delta gives a valid Gaussian.

use super::field::WarpKind;

/// One Gaussian's deformable parameters.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub mean: [f64; 3],
    pub log_scale: [f64; 3],
    pub rotation: [f64; 4],
}

/// Below this screw angle the Rodrigues coefficients come from their Taylor series (the closed
/// forms lose every digit in f32 there).
pub const SMALL_ANGLE: f64 = 1.0e-2;

/// `sin t / t`, `(1 - cos t) / t^2`, `(t - sin t) / t^3` and their derivatives divided by `t`.
#[derive(Debug, Clone, Copy)]
struct ScrewCoefficients {
    a: f64,
    b: f64,
    c: f64,
    da_over_t: f64,
    db_over_t: f64,
    dc_over_t: f64,
}

fn screw_coefficients(theta_squared: f64) -> ScrewCoefficients {
    let t2 = theta_squared;
    let theta = t2.sqrt();
    if theta < SMALL_ANGLE {
        return ScrewCoefficients {
            a: 1.0 - t2 / 6.0 + t2 * t2 / 120.0,
            b: 0.5 - t2 / 24.0 + t2 * t2 / 720.0,
            c: 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
            da_over_t: -1.0 / 3.0 + t2 / 30.0,
            db_over_t: -1.0 / 12.0 + t2 / 180.0,
            dc_over_t: -1.0 / 60.0 + t2 / 1260.0,
        };
    }
    let (sin, cos) = theta.sin_cos();
    let t3 = t2 * theta;
    let t4 = t2 * t2;
    let t5 = t4 * theta;
    ScrewCoefficients {
        a: sin / theta,
        b: (1.0 - cos) / t2,
        c: (theta - sin) / t3,
        da_over_t: (theta * cos - sin) / t3,
        db_over_t: (theta * sin - 2.0 * (1.0 - cos)) / t4,
        dc_over_t: (1.0 - cos) / t4 - 3.0 * (theta - sin) / t5,
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn axpy(alpha: f64, x: [f64; 3], y: [f64; 3]) -> [f64; 3] {
    [
        alpha * x[0] + y[0],
        alpha * x[1] + y[1],
        alpha * x[2] + y[2],
    ]
}

/// `exp([w, v]) x = x + a (w x x) + b w x (w x x) + v + b (w x v) + c w x (w x v)`.
fn screw_apply(w: [f64; 3], v: [f64; 3], x: [f64; 3]) -> [f64; 3] {
    let k = screw_coefficients(dot(w, w));
    let wx = cross(w, x);
    let wwx = cross(w, wx);
    let wv = cross(w, v);
    let wwv = cross(w, wv);
    let mut out = x;
    out = axpy(k.a, wx, out);
    out = axpy(k.b, wwx, out);
    out = axpy(1.0, v, out);
    out = axpy(k.b, wv, out);
    axpy(k.c, wwv, out)
}

/// Gradients of `g . screw_apply(w, v, x)` with respect to `w`, `v` and `x`.
fn screw_backward(w: [f64; 3], v: [f64; 3], x: [f64; 3], g: [f64; 3]) -> [[f64; 3]; 3] {
    let t2 = dot(w, w);
    let k = screw_coefficients(t2);
    let (gw, gx, gv) = (dot(g, w), dot(g, x), dot(g, v));
    let (wx, wv) = (dot(w, x), dot(w, v));
    // d/dw of g.(w x p) is p x g; of g.(w x (w x p)) = (w.p)(g.w) - t2 (g.p) is
    // p (g.w) + g (w.p) - 2 w (g.p); each coefficient adds (its derivative / t) w times its term.
    let x_cross_g = cross(x, g);
    let v_cross_g = cross(v, g);
    let mut grad_w = [0.0; 3];
    for i in 0..3 {
        grad_w[i] = k.a * x_cross_g[i]
            + k.b * (x[i] * gw + g[i] * wx - 2.0 * w[i] * gx)
            + k.b * v_cross_g[i]
            + k.c * (v[i] * gw + g[i] * wv - 2.0 * w[i] * gv);
    }
    let radial = k.da_over_t * dot(w, x_cross_g)
        + k.db_over_t * (wx * gw - t2 * gx)
        + k.db_over_t * dot(w, v_cross_g)
        + k.dc_over_t * (wv * gw - t2 * gv);
    grad_w = axpy(radial, w, grad_w);
    // The map is linear in v and x: V(w)^T g and R(w)^T g, with R^T = R(-w) and V^T = V(-w).
    let minus_w = [-w[0], -w[1], -w[2]];
    let grad_x = rotate(minus_w, g, &k);
    let wg = cross(minus_w, g);
    let grad_v = axpy(k.c, cross(minus_w, wg), axpy(k.b, wg, g));
    [grad_w, grad_v, grad_x]
}

fn rotate(w: [f64; 3], x: [f64; 3], k: &ScrewCoefficients) -> [f64; 3] {
    let wx = cross(w, x);
    axpy(k.b, cross(w, wx), axpy(k.a, wx, x))
}

fn normalised(q: [f64; 4]) -> ([f64; 4], f64) {
    let norm = (q.iter().map(|c| c * c).sum::<f64>()).sqrt().max(1e-12);
    (q.map(|c| c / norm), norm)
}

/// The deformed pose given the head's outputs for this Gaussian.
pub fn warp(kind: WarpKind, canonical: &Pose, head: &[f64]) -> Pose {
    let position = kind.outputs();
    let mean = match kind {
        WarpKind::Translation => [0, 1, 2].map(|i| canonical.mean[i] + head[i]),
        WarpKind::Screw => screw_apply(
            [head[0], head[1], head[2]],
            [head[3], head[4], head[5]],
            canonical.mean,
        ),
    };
    let (unit, _) = normalised(canonical.rotation);
    Pose {
        mean,
        rotation: [0, 1, 2, 3].map(|i| unit[i] + head[position + i]),
        log_scale: [0, 1, 2].map(|i| canonical.log_scale[i] + head[position + 4 + i]),
    }
}

/// Chain rule through [`warp`]: given `d loss / d deformed pose`, returns `d loss / d canonical
/// pose` and `d loss / d head outputs`.
pub fn warp_backward(
    kind: WarpKind,
    canonical: &Pose,
    head: &[f64],
    grad_deformed: &Pose,
) -> (Pose, Vec<f64>) {
    let position = kind.outputs();
    let mut grad_head = vec![0.0; position + 7];
    let grad_mean = match kind {
        WarpKind::Translation => {
            grad_head[..3].copy_from_slice(&grad_deformed.mean);
            grad_deformed.mean
        }
        WarpKind::Screw => {
            let [grad_w, grad_v, grad_x] = screw_backward(
                [head[0], head[1], head[2]],
                [head[3], head[4], head[5]],
                canonical.mean,
                grad_deformed.mean,
            );
            grad_head[..3].copy_from_slice(&grad_w);
            grad_head[3..6].copy_from_slice(&grad_v);
            grad_x
        }
    };
    grad_head[position..position + 4].copy_from_slice(&grad_deformed.rotation);
    grad_head[position + 4..].copy_from_slice(&grad_deformed.log_scale);
    let (unit, norm) = normalised(canonical.rotation);
    let g = grad_deformed.rotation;
    let along: f64 = (0..4).map(|i| unit[i] * g[i]).sum();
    let grad_rotation = [0, 1, 2, 3].map(|i| (g[i] - unit[i] * along) / norm);
    (
        Pose {
            mean: grad_mean,
            log_scale: grad_deformed.log_scale,
            rotation: grad_rotation,
        },
        grad_head,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn objective(kind: WarpKind, pose: &Pose, head: &[f64], weights: &Pose) -> f64 {
        let out = warp(kind, pose, head);
        dot(out.mean, weights.mean)
            + dot(out.log_scale, weights.log_scale)
            + (0..4)
                .map(|i| out.rotation[i] * weights.rotation[i])
                .sum::<f64>()
    }

    fn check_gradients(kind: WarpKind, head: Vec<f64>) {
        let pose = Pose {
            mean: [0.3, -0.7, 1.1],
            log_scale: [-1.0, -2.0, -0.5],
            rotation: [0.9, 0.2, -0.3, 0.4],
        };
        let weights = Pose {
            mean: [0.5, -1.5, 0.25],
            log_scale: [1.0, 0.3, -0.2],
            rotation: [0.1, 0.7, -0.4, 0.2],
        };
        let (grad_pose, grad_head) = warp_backward(kind, &pose, &head, &weights);
        let h = 1e-6;
        for i in 0..head.len() {
            let mut plus = head.clone();
            let mut minus = head.clone();
            plus[i] += h;
            minus[i] -= h;
            let numeric = (objective(kind, &pose, &plus, &weights)
                - objective(kind, &pose, &minus, &weights))
                / (2.0 * h);
            assert!(
                (numeric - grad_head[i]).abs() < 1e-6,
                "{kind:?} head {i}: {numeric} vs {}",
                grad_head[i]
            );
        }
        for i in 0..3 {
            let mut plus = pose;
            let mut minus = pose;
            plus.mean[i] += h;
            minus.mean[i] -= h;
            let numeric = (objective(kind, &plus, &head, &weights)
                - objective(kind, &minus, &head, &weights))
                / (2.0 * h);
            assert!((numeric - grad_pose.mean[i]).abs() < 1e-6, "mean {i}");
        }
        for i in 0..4 {
            let mut plus = pose;
            let mut minus = pose;
            plus.rotation[i] += h;
            minus.rotation[i] -= h;
            let numeric = (objective(kind, &plus, &head, &weights)
                - objective(kind, &minus, &head, &weights))
                / (2.0 * h);
            assert!(
                (numeric - grad_pose.rotation[i]).abs() < 1e-6,
                "rotation {i}"
            );
        }
    }

    #[test]
    fn translation_gradients_match_finite_differences() {
        check_gradients(
            WarpKind::Translation,
            (0..10).map(|i| 0.05 * i as f64).collect(),
        );
    }

    #[test]
    fn screw_gradients_match_finite_differences_at_large_and_small_angles() {
        let mut head: Vec<f64> = vec![0.4, -0.3, 0.8, 0.2, 0.1, -0.5];
        head.extend([0.01, 0.02, 0.0, -0.01, 0.1, 0.0, -0.1]);
        check_gradients(WarpKind::Screw, head.clone());
        head[..3].copy_from_slice(&[2e-3, -1e-3, 4e-3]);
        check_gradients(WarpKind::Screw, head);
    }

    #[test]
    fn screw_is_a_rigid_motion() {
        // A quarter turn about z with no translation moves x onto y.
        let angle = std::f64::consts::FRAC_PI_2;
        let moved = screw_apply([0.0, 0.0, angle], [0.0; 3], [1.0, 0.0, 0.0]);
        assert!((moved[0]).abs() < 1e-12 && (moved[1] - 1.0).abs() < 1e-12);
        // Pure translation when w = 0.
        let moved = screw_apply([0.0; 3], [0.1, 0.2, 0.3], [1.0, 1.0, 1.0]);
        assert_eq!(moved, [1.1, 1.2, 1.3]);
    }
}
