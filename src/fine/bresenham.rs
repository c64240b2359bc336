//! Reversible Bresenham in up to six axes.
//!
//! A block from lattice point `a` to `b` takes `n = max |b_i - a_i|` *events*; at event `k` the
//! position of axis `i` is
//!
//! ```text
//! p_i(k) = a_i + sign(d_i) * floor((2 |d_i| k + n) / 2n)          d = b - a
//! ```
//!
//! the lattice point nearest to the straight line at the long axis' `k`-th step (ties towards
//! `a`). That is a function of `k` alone, so walking from `k` to `k + 1` and from `k + 1` back to
//! `k` visit the same points, and `p(n) = b` exactly. The walk keeps it incrementally with one
//! integer error term per axis, `e_i = (2 |d_i| k + n) mod 2n`: forward adds `2|d_i|` and steps
//! on a carry, backward subtracts and steps on a borrow. Since `|d_i| <= n` an event moves each
//! axis by at most one step, and the long axis by exactly one.

use crate::vocab::{MAX_AXES, Steps};

/// The walk along one block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bresenham {
    /// Events of the block (steps of the long axis).
    n: i64,
    /// Current event, `0..=n`.
    k: i64,
    /// `2 |d_i|`.
    rise: Steps,
    sign: [i8; MAX_AXES],
    /// `(2 |d_i| k + n) mod 2n`.
    err: Steps,
}

impl Bresenham {
    /// A walk over `delta` steps per axis, positioned at event `0` (or at event `n` when
    /// `at_end`, for a block entered backwards).
    pub fn new(delta: &Steps, at_end: bool) -> Bresenham {
        let n = delta.iter().map(|d| d.abs()).max().unwrap_or(0);
        let mut walk = Bresenham {
            n,
            k: 0,
            rise: std::array::from_fn(|i| 2 * delta[i].abs()),
            sign: std::array::from_fn(|i| delta[i].signum() as i8),
            err: [n; MAX_AXES],
        };
        if at_end && n > 0 {
            walk.k = n;
            // (2|d| n + n) mod 2n = n whatever |d| is: the same residue as at k = 0.
        }
        walk
    }

    pub fn events(&self) -> i64 {
        self.n
    }

    /// Current event index, `0..=events()`.
    pub fn event(&self) -> i64 {
        self.k
    }

    pub fn at_start(&self) -> bool {
        self.k == 0
    }

    pub fn at_end(&self) -> bool {
        self.k == self.n
    }

    /// One event forward; the signed step of each axis goes to `steps`. The caller checks
    /// `at_end()` first.
    #[inline]
    pub fn forward(&mut self, steps: &mut [i8; MAX_AXES]) {
        debug_assert!(self.k < self.n);
        self.k += 1;
        let two_n = 2 * self.n;
        for ((err, step), (&rise, &sign)) in self
            .err
            .iter_mut()
            .zip(steps.iter_mut())
            .zip(self.rise.iter().zip(&self.sign))
        {
            let e = *err + rise;
            let carry = e >= two_n;
            *err = if carry { e - two_n } else { e };
            *step = if carry { sign } else { 0 };
        }
    }

    /// One event backward, exactly undoing [`forward`](Self::forward). The caller checks
    /// `at_start()` first.
    #[inline]
    pub fn backward(&mut self, steps: &mut [i8; MAX_AXES]) {
        debug_assert!(self.k > 0);
        self.k -= 1;
        let two_n = 2 * self.n;
        for ((err, step), (&rise, &sign)) in self
            .err
            .iter_mut()
            .zip(steps.iter_mut())
            .zip(self.rise.iter().zip(&self.sign))
        {
            let e = *err - rise;
            let borrow = e < 0;
            *err = if borrow { e + two_n } else { e };
            *step = if borrow { -sign } else { 0 };
        }
    }

    /// The position offset from the block's start at event `k`, from the closed form (for
    /// tests and for checking the incremental walk).
    pub fn offset_at(delta: &Steps, k: i64) -> Steps {
        let n = delta.iter().map(|d| d.abs()).max().unwrap_or(0);
        if n == 0 {
            return [0; MAX_AXES];
        }
        std::array::from_fn(|i| {
            delta[i].signum()
                * ((2 * delta[i].abs() as i128 * k as i128 + n as i128) / (2 * n as i128)) as i64
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn delta_strategy() -> impl Strategy<Value = Steps> {
        (
            1usize..=MAX_AXES,
            proptest::collection::vec(-300i64..300, MAX_AXES),
        )
            .prop_map(|(axes, v)| std::array::from_fn(|i| if i < axes { v[i] } else { 0 }))
    }

    fn add(pos: &mut Steps, steps: &[i8; MAX_AXES]) {
        for i in 0..MAX_AXES {
            pos[i] += steps[i] as i64;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// Exact end point, at most one step per axis per event, the long axis steps every
        /// event, and the walk agrees with the closed form at every event.
        #[test]
        fn forward_is_exact(delta in delta_strategy()) {
            let mut walk = Bresenham::new(&delta, false);
            let mut pos = [0i64; MAX_AXES];
            let mut steps = [0i8; MAX_AXES];
            while !walk.at_end() {
                walk.forward(&mut steps);
                prop_assert!(steps.iter().all(|s| (-1..=1).contains(s)));
                prop_assert!(steps.iter().any(|&s| s != 0), "an event that moves nothing");
                add(&mut pos, &steps);
                prop_assert_eq!(pos, Bresenham::offset_at(&delta, walk.event()));
            }
            prop_assert_eq!(pos, delta);
            prop_assert_eq!(walk.event(), delta.iter().map(|d| d.abs()).max().unwrap());
        }

        /// The backward walk from the end visits the forward points in reverse, whether the
        /// block is entered backwards at its end or reversed part-way.
        #[test]
        fn backward_retraces(delta in delta_strategy(), turn in 0.0f64..1.0) {
            let mut walk = Bresenham::new(&delta, false);
            let mut steps = [0i8; MAX_AXES];
            let mut pos = [0i64; MAX_AXES];
            let mut visited = vec![pos];
            let stop = (walk.events() as f64 * turn) as i64;
            while walk.event() < stop {
                walk.forward(&mut steps);
                add(&mut pos, &steps);
                visited.push(pos);
            }
            while !walk.at_start() {
                walk.backward(&mut steps);
                add(&mut pos, &steps);
                visited.pop();
                prop_assert_eq!(Some(&pos), visited.last());
            }
            // Entered at the end and walked back: the closed form in reverse.
            let mut back = Bresenham::new(&delta, true);
            let mut pos = delta;
            while !back.at_start() {
                back.backward(&mut steps);
                add(&mut pos, &steps);
                prop_assert_eq!(pos, Bresenham::offset_at(&delta, back.event()));
            }
            prop_assert_eq!(pos, [0; MAX_AXES]);
        }

        /// A chain of blocks between rounded points ends exactly on the last point, and the
        /// same chain walked back returns exactly to the first.
        #[test]
        fn chains_stay_exact(points in proptest::collection::vec(
            proptest::collection::vec(-1000i64..1000, 3), 2..20)) {
            let lattice: Vec<Steps> = points
                .iter()
                .map(|p| std::array::from_fn(|i| if i < 3 { p[i] } else { 0 }))
                .collect();
            let mut pos = lattice[0];
            let mut steps = [0i8; MAX_AXES];
            for pair in lattice.windows(2) {
                let delta = std::array::from_fn(|i| pair[1][i] - pair[0][i]);
                let mut walk = Bresenham::new(&delta, false);
                while !walk.at_end() {
                    walk.forward(&mut steps);
                    add(&mut pos, &steps);
                }
                prop_assert_eq!(pos, pair[1]);
            }
            for pair in lattice.windows(2).rev() {
                let delta = std::array::from_fn(|i| pair[1][i] - pair[0][i]);
                let mut walk = Bresenham::new(&delta, true);
                while !walk.at_start() {
                    walk.backward(&mut steps);
                    add(&mut pos, &steps);
                }
                prop_assert_eq!(pos, pair[0]);
            }
        }
    }

    #[test]
    fn a_zero_block_has_no_events() {
        let walk = Bresenham::new(&[0; MAX_AXES], false);
        assert!(walk.at_start() && walk.at_end());
    }
}
