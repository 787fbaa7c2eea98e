//! motorbench: commissions electric motors on a test rig.
//!
//! Map of the crate (data flows top to bottom):
//!
//! - [`config`]: rig and test configuration (TOML), validated;
//!   [`config::TestConfig`] names the test plan ([`config::PlanKind`],
//!   `test.plan`), for the CLI, the daemon and the tests alike; the keys
//!   every machine's file shares (motor, sample rate, limits, supervisor,
//!   records, faults) are validated once into a [`config::CommonConfig`].
//! - [`contract`]: the data contract's serde types (the identification
//!   report, the diagnosis, the version); depends on nothing else here.
//! - [`bounds`]: the practical bounds on every number from outside that
//!   sizes an allocation, a loop or a wait.
//! - [`excerpt`]: user input quoted in error messages, long values cut.
//! - [`model`]: DC machine equations, effects, exact simulation; the
//!   induction machine's steady-state equivalent circuits, and its
//!   augmentations (`model::im_effects`: saturation, core loss, deep bar,
//!   …) that the diagnosis and the standard tests' joint fit share.
//! - [`bench`]: machine-agnostic: settle detection, limits and safe state.
//!   Every test reads through one sequencer core (`bench/sequencer.rs`:
//!   select on the stop, stale-data timeout, recording, the
//!   [`bench::SafetyMonitor`] checked synchronously on every batch); the
//!   DC steps and the IM sweep are plans on top of it, in [`machine`].
//!   `run` and the daemon share that safety path, under the one
//!   supervisor task ([`bench::supervise`]: heartbeat, bus loss, stops,
//!   latching) that [`session`] starts with every record.
//! - [`rig`]: what every machine's rig shares (Modbus clients and bus
//!   sharing, the simulated device served behind a profile), and the
//!   faults a test's `[[fault]]` array injects into it ([`rig::fault`]).
//! - [`machine`]: what differs between machines, behind one trait
//!   ([`machine::Machine`]: the plan's steps, the rig's stages, the
//!   record's channels, the analysis and its report); the DC machine
//!   (`machine/dc/`) and the induction machine (`machine/im/`) implement
//!   it, each folder holding its plan, rigs, identification
//!   (`identify/`), diagnosis (`diagnose/`), text and plots.
//!   [`config::TestConfig::into_machine`] is the one place a plan is
//!   mapped to its machine.
//! - [`session`]: one test, whatever the machine: rig → supervisor →
//!   recorder → plan → analysis off the reactor → `/bench/result` →
//!   files. `run` ([`session::commission`]), the daemon's jobs and the
//!   tests all go through it.
//! - [`record`]: MCAP recorder and reader per the data contract, CSV import.
//! - [`identify`]: the public paths of each machine's identification and
//!   the numerics they share.
//! - [`diagnose`]: the sim-to-real gap: what both machines' diagnoses
//!   share (the held-out decision, residual plots, text, the blind
//!   benchmark) and their public paths.
//! - [`report`]: JSON, SVG time-series plots; each machine's text and
//!   plots by their public paths.
//! - [`cli`]: the bodies of the `run`, `probe`, `replay` and `identify`
//!   subcommands and their exit codes; none of them branches on the
//!   machine.
//! - [`serve`]: the daemon (`motorbench serve`): control API, one test at
//!   a time per rig under the safety supervisor, records index, systemd;
//!   and its client (`motorbench ctl`).
//!
//! The binary (`src/main.rs`) only parses the command line (clap) and
//! dispatches to [`cli`], [`diagnose::cli`] and [`serve::cli`].

pub mod bench;
pub mod bounds;
pub mod cli;
pub mod config;
pub mod contract;
pub mod diagnose;
pub mod excerpt;
pub mod fuzz;
pub mod identify;
pub mod machine;
pub mod model;
pub mod record;
pub mod report;
pub mod rig;
pub mod serve;
pub mod session;
