//! The three linear axes of a Cartesian machine and their travel.

use nalgebra::{Point3, Vector3};

/// A linear machine axis. The machine coordinate system is right-handed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// All axes in index order.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Index 0, 1, 2 for X, Y, Z.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The axis with index `i` (0, 1, 2).
    pub fn from_index(i: usize) -> Axis {
        Axis::ALL[i]
    }

    /// Unit vector along the axis.
    pub fn unit(self) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        v[self.index()] = 1.0;
        v
    }

    /// Linear name letter: `X`, `Y`, `Z`.
    pub fn letter(self) -> char {
        ['X', 'Y', 'Z'][self.index()]
    }

    /// Rotary name letter of a rotation about this axis (ISO 841): `A`, `B`, `C`.
    pub fn rotary_letter(self) -> char {
        ['A', 'B', 'C'][self.index()]
    }

    /// Parses `x`/`X`, `y`/`Y`, `z`/`Z`.
    pub fn from_letter(c: char) -> Option<Axis> {
        match c.to_ascii_uppercase() {
            'X' => Some(Axis::X),
            'Y' => Some(Axis::Y),
            'Z' => Some(Axis::Z),
            _ => None,
        }
    }

    /// Coordinate of a point along this axis.
    pub fn coord(self, p: &Point3<f64>) -> f64 {
        p[self.index()]
    }
}

/// Travel (stroke) of the three axes in metres, `[lo, hi]` per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Travel {
    pub ranges: [[f64; 2]; 3],
}

impl Travel {
    /// Travel from per-axis `[lo, hi]` ranges (metres).
    pub fn new(x: [f64; 2], y: [f64; 2], z: [f64; 2]) -> Travel {
        Travel { ranges: [x, y, z] }
    }

    /// `[lo, hi]` of an axis.
    pub fn range(&self, a: Axis) -> [f64; 2] {
        self.ranges[a.index()]
    }

    /// Length of an axis's travel.
    pub fn length(&self, a: Axis) -> f64 {
        let [lo, hi] = self.range(a);
        hi - lo
    }

    /// Length of the working volume's diagonal.
    pub fn diagonal(&self) -> f64 {
        (self.max_corner() - self.min_corner()).norm()
    }

    /// Lower corner of the working volume.
    pub fn min_corner(&self) -> Point3<f64> {
        Point3::new(self.ranges[0][0], self.ranges[1][0], self.ranges[2][0])
    }

    /// Upper corner of the working volume.
    pub fn max_corner(&self) -> Point3<f64> {
        Point3::new(self.ranges[0][1], self.ranges[1][1], self.ranges[2][1])
    }

    /// Centre of the working volume.
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min_corner(), &self.max_corner())
    }

    /// Whether `p` lies inside the travel, with a tolerance in metres.
    pub fn contains(&self, p: &Point3<f64>, tol: f64) -> bool {
        Axis::ALL.iter().all(|&a| {
            let [lo, hi] = self.range(a);
            let c = a.coord(p);
            c >= lo - tol && c <= hi + tol
        })
    }

    /// Checks that every range is finite and has positive length.
    pub fn validate(&self) -> Result<(), String> {
        for a in Axis::ALL {
            let [lo, hi] = self.range(a);
            if !lo.is_finite() || !hi.is_finite() {
                return Err(format!("travel of {} is not finite: [{lo}, {hi}]", a.letter()));
            }
            if hi <= lo {
                return Err(format!("travel of {} must have lo < hi, got [{lo}, {hi}]", a.letter()));
            }
        }
        Ok(())
    }
}
