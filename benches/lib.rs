//! edmd's criterion benchmarks, a package of their own so that criterion and curvo (the
//! reference NURBS library `geometry` compares with) are built only to bench:
//!
//! ```text
//! cargo bench -p edmd-benches                      # all of them
//! cargo bench -p edmd-benches --bench geometry     # one
//! ```
//!
//! The benches are the files beside this one; `BENCHMARKS.md` has what they measured.
