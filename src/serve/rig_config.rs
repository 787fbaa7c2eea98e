//! A rig's configuration as the daemon holds it: the one
//! [`TestConfig`](crate::config::TestConfig) (a DC rig, `dc_step` /
//! `dc_coastdown`; an induction-machine rig, `im_slip_sweep` or
//! `im_standard_tests`), with a start request's `[test]` applied over it
//! by [`TestConfig::with_test`](crate::config::TestConfig::with_test).

pub use crate::config::TestConfig as RigConfig;
