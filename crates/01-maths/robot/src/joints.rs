//! [`Joints`]: an arm's joint positions, six for every UR arm and up to seven for the arms a lab
//! drives over ROS 2 (Franka, KUKA iiwa, Kinova Gen3).

use std::fmt;
use std::ops::{Deref, DerefMut};

/// The most joints an arm handeye drives may have: seven (Franka, KUKA iiwa, Kinova Gen3).
pub const MAX_JOINTS: usize = 7;

/// Joint positions in radians (or joint speeds in rad/s), base joint first: six on every UR arm,
/// one to [`MAX_JOINTS`] on an arm driven over ROS 2. Fixed-size and `Copy` — plans, records and
/// moves copy them freely — and read as the slice of its joints (`q[2]`, `q.iter()`, `q.len()`).
#[derive(Clone, Copy)]
pub struct Joints {
    len: u8,
    values: [f64; MAX_JOINTS],
}

/// A joint list that is empty or longer than [`MAX_JOINTS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("expected 1 to {MAX_JOINTS} joints, found {0}")]
pub struct JointCountError(pub usize);

impl Joints {
    /// The joints in `values`, base first.
    pub fn from_slice(values: &[f64]) -> Result<Joints, JointCountError> {
        if values.is_empty() || values.len() > MAX_JOINTS {
            return Err(JointCountError(values.len()));
        }
        let mut out = Joints {
            len: values.len() as u8,
            values: [0.0; MAX_JOINTS],
        };
        out.values[..values.len()].copy_from_slice(values);
        Ok(out)
    }

    /// `count` joints, each `f(i)`. `count` must be 1 to [`MAX_JOINTS`] (a caller's constant or
    /// the length of joints it already holds).
    pub fn from_fn(count: usize, f: impl FnMut(usize) -> f64) -> Joints {
        assert!(
            (1..=MAX_JOINTS).contains(&count),
            "joint count {count} outside 1..={MAX_JOINTS}"
        );
        let mut out = Joints {
            len: count as u8,
            values: [0.0; MAX_JOINTS],
        };
        out.values[..count]
            .iter_mut()
            .zip((0..count).map(f))
            .for_each(|(v, x)| *v = x);
        out
    }

    /// A six-joint arm's joints (a UR's); `const`, for named configurations.
    pub const fn from_six(q: [f64; 6]) -> Joints {
        Joints {
            len: 6,
            values: [q[0], q[1], q[2], q[3], q[4], q[5], 0.0],
        }
    }

    /// `count` zeros (an arm at rest: its joint speeds).
    pub fn zeros(count: usize) -> Joints {
        Joints::from_fn(count, |_| 0.0)
    }

    /// The six joints of a six-joint arm (a UR), or `None` for any other count.
    pub fn six(&self) -> Option<[f64; 6]> {
        <[f64; 6]>::try_from(&**self).ok()
    }
}

impl From<[f64; 6]> for Joints {
    fn from(values: [f64; 6]) -> Joints {
        Joints::from_six(values)
    }
}

impl From<[f64; 7]> for Joints {
    fn from(values: [f64; 7]) -> Joints {
        Joints::from_fn(7, |i| values[i])
    }
}

impl Deref for Joints {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        &self.values[..self.len as usize]
    }
}

impl DerefMut for Joints {
    fn deref_mut(&mut self) -> &mut [f64] {
        &mut self.values[..self.len as usize]
    }
}

impl<'a> IntoIterator for &'a Joints {
    type Item = &'a f64;
    type IntoIter = std::slice::Iter<'a, f64>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl PartialEq for Joints {
    fn eq(&self, other: &Joints) -> bool {
        **self == **other
    }
}

impl PartialEq<[f64; 6]> for Joints {
    fn eq(&self, other: &[f64; 6]) -> bool {
        **self == other[..]
    }
}

impl fmt::Debug for Joints {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn six_and_seven_joints_read_as_their_slices() {
        let ur = Joints::from([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]);
        assert_eq!(ur.len(), 6);
        assert_eq!(ur[1], -1.57);
        assert_eq!(ur.six(), Some([0.0, -1.57, 1.57, -1.57, -1.57, 0.0]));
        let iiwa = Joints::from_slice(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]).unwrap();
        assert_eq!(iiwa.len(), 7);
        assert_eq!(iiwa[6], 0.7);
        assert!((iiwa.iter().sum::<f64>() - 2.8).abs() < 1e-12);
        assert_eq!(iiwa.six(), None);
        assert_ne!(Joints::zeros(6), Joints::zeros(7));
        let mut q = Joints::zeros(7);
        q[6] = 1.0;
        assert_eq!(q[6], 1.0);
        assert_eq!(format!("{:?}", Joints::zeros(2)), "[0.0, 0.0]");
    }

    #[test]
    fn an_empty_or_eight_joint_list_is_refused() {
        assert_eq!(Joints::from_slice(&[]), Err(JointCountError(0)));
        assert_eq!(Joints::from_slice(&[0.0; 8]), Err(JointCountError(8)));
        assert_eq!(
            JointCountError(8).to_string(),
            "expected 1 to 7 joints, found 8"
        );
    }
}
