//! The stability scenarios over every method, and property tests of the
//! solvers on random cloths (one test binary).

mod fuzz;
mod stability;
