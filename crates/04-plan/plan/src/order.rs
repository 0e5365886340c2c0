//! Visiting order for travel time: the poses of a plan as an open tour from where the arm
//! stands, with the cost of a move its duration at the configured limits
//! ([`MotionLimits::joint_move_time`](handeye_robot::MotionLimits::joint_move_time), the
//! trapezoidal `moveJ` the session sends). Nearest neighbour builds a first tour; 2-opt (reverse
//! a stretch) and Or-opt (move a run of up to three poses elsewhere, either way round) improve it
//! until no move helps. A move the caller forbids (it would leave the joint ranges or the
//! workspace box) costs [`FORBIDDEN_S`], so a tour uses one only when nothing else connects.
//!
//! The caller re-checks the tour it gets (reach from the new previous pose, box along every
//! path) and keeps the given order when the tour is not better: this module only searches.

use handeye_robot::Joints;

/// The cost of a forbidden move, s: larger than any real tour.
pub const FORBIDDEN_S: f64 = 1e6;

/// Improvement rounds at most (each round tries every 2-opt and Or-opt move once).
const MAX_ROUNDS: usize = 200;

/// Largest plan that Or-opt also improves.
const OR_OPT_MAX_POSES: usize = 150;

/// Smallest gain a step must make, s (stops float ping-pong).
const EPS_S: f64 = 1e-9;

/// The order (indices into `poses`) that visits every pose once, starting from `start`, with
/// the least total move time found; `cost(a, b)` is the time of the move from `a` to `b`, or
/// `None` when that move is forbidden. Deterministic.
pub fn order_for_travel(
    start: &Joints,
    poses: &[Joints],
    cost: impl Fn(&Joints, &Joints) -> Option<f64>,
) -> Vec<usize> {
    let n = poses.len();
    if n < 2 {
        return (0..n).collect();
    }
    // Node 0 is the start, node k + 1 is pose k.
    let node = |k: usize| if k == 0 { start } else { &poses[k - 1] };
    let c: Vec<Vec<f64>> = (0..=n)
        .map(|a| {
            (0..=n)
                .map(|b| {
                    if a == b {
                        0.0
                    } else {
                        cost(node(a), node(b)).unwrap_or(FORBIDDEN_S)
                    }
                })
                .collect()
        })
        .collect();
    let mut tour = nearest_neighbour(&c);
    for _ in 0..MAX_ROUNDS {
        // Or-opt as written costs O(n³) a round: for the plan sizes people run (tens), not for
        // a thousand poses, where 2-opt alone still does well.
        let improved = two_opt(&c, &mut tour) | (n <= OR_OPT_MAX_POSES && or_opt(&c, &mut tour));
        if !improved {
            break;
        }
    }
    tour[1..].iter().map(|k| k - 1).collect()
}

/// Total time of an open tour (node 0 first), s.
pub fn tour_time(c: &[Vec<f64>], tour: &[usize]) -> f64 {
    tour.windows(2).map(|w| c[w[0]][w[1]]).sum()
}

fn nearest_neighbour(c: &[Vec<f64>]) -> Vec<usize> {
    let n = c.len();
    let mut tour = vec![0];
    let mut used = vec![false; n];
    used[0] = true;
    for _ in 1..n {
        let last = tour[tour.len() - 1];
        let next = (0..n)
            .filter(|&k| !used[k])
            .min_by(|&a, &b| c[last][a].total_cmp(&c[last][b]))
            .unwrap_or(0);
        used[next] = true;
        tour.push(next);
    }
    tour
}

/// One pass of 2-opt on the open tour (position 0 stays first): reverse `tour[i..=j]` when that
/// shortens it. Whether anything changed.
fn two_opt(c: &[Vec<f64>], tour: &mut [usize]) -> bool {
    let n = tour.len();
    let mut improved = false;
    for i in 1..n - 1 {
        // The reversed stretch runs the other way round: its inner moves count too (the costs
        // need not be symmetric). Summed as `j` grows.
        let (mut inner_fwd, mut inner_rev) = (0.0, 0.0);
        for j in i + 1..n {
            inner_fwd += c[tour[j - 1]][tour[j]];
            inner_rev += c[tour[j]][tour[j - 1]];
            let (a, b, d) = (tour[i - 1], tour[i], tour[j]);
            let mut before = c[a][b];
            let mut after = c[a][d];
            if j + 1 < n {
                let e = tour[j + 1];
                before += c[d][e];
                after += c[b][e];
            }
            if after + inner_rev + EPS_S < before + inner_fwd {
                tour[i..=j].reverse();
                improved = true;
                // The sums describe the old stretch: go on from the next start.
                break;
            }
        }
    }
    improved
}

/// One pass of Or-opt: move a run of 1 to 3 poses to another place in the tour, forwards or
/// reversed, when that shortens it. Whether anything changed.
fn or_opt(c: &[Vec<f64>], tour: &mut Vec<usize>) -> bool {
    let mut improved = false;
    for len in 1..=3usize {
        let mut i = 1;
        while i + len <= tour.len() {
            let current = tour_time(c, tour);
            let run: Vec<usize> = tour[i..i + len].to_vec();
            let mut rest: Vec<usize> = tour[..i].to_vec();
            rest.extend_from_slice(&tour[i + len..]);
            let mut best: Option<(f64, Vec<usize>)> = None;
            for at in 1..=rest.len() {
                for reversed in [false, true] {
                    let mut candidate = rest[..at].to_vec();
                    if reversed {
                        candidate.extend(run.iter().rev());
                    } else {
                        candidate.extend_from_slice(&run);
                    }
                    candidate.extend_from_slice(&rest[at..]);
                    let time = tour_time(c, &candidate);
                    if time + EPS_S < best.as_ref().map_or(current, |b| b.0) {
                        best = Some((time, candidate));
                    }
                }
            }
            if let Some((_, better)) = best {
                *tour = better;
                improved = true;
            }
            i += 1;
        }
    }
    improved
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_robot::MotionLimits;

    fn at(x: f64) -> Joints {
        Joints::from([x, 0.0, 0.0, 0.0, 0.0, 0.0])
    }

    #[test]
    fn poses_on_a_line_are_visited_in_sweep_order() {
        let limits = MotionLimits::default();
        let poses: Vec<Joints> = [0.9, 0.1, 0.5, 0.3, 0.7, 0.2].map(at).to_vec();
        let order = order_for_travel(&at(0.0), &poses, |a, b| Some(limits.joint_move_time(a, b)));
        let visited: Vec<f64> = order.iter().map(|&k| poses[k][0]).collect();
        assert_eq!(visited, vec![0.1, 0.2, 0.3, 0.5, 0.7, 0.9]);
    }

    #[test]
    fn forbidden_moves_are_avoided_when_a_detour_exists() {
        // Straight from 0.1 to 0.2 is forbidden (say it crosses the box): the tour must not use
        // that move, though it is the shortest.
        let poses: Vec<Joints> = [0.1, 0.2, 0.3].map(at).to_vec();
        let forbidden = |a: &Joints, b: &Joints| {
            let (x, y) = (a[0].min(b[0]), a[0].max(b[0]));
            (x - 0.1).abs() < 1e-12 && (y - 0.2).abs() < 1e-12
        };
        let order = order_for_travel(&at(0.0), &poses, |a, b| {
            (!forbidden(a, b)).then(|| (a[0] - b[0]).abs())
        });
        let mut tour = vec![at(0.0)];
        tour.extend(order.iter().map(|&k| poses[k]));
        assert!(
            tour.windows(2).all(|w| !forbidden(&w[0], &w[1])),
            "{order:?}"
        );
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, vec![0, 1, 2]);
    }
}
