//! Reports for people and programs: JSON per the contract, SVG time-series
//! plots, and the public paths of each machine's text and plots (which
//! live with the machine: `machine/dc/text.rs`, `overlay.rs`;
//! `machine/im/text.rs`, `plot.rs`).

pub mod legend;
pub mod plot;

pub use crate::contract::{
    unphysical_param, IdentificationReport, MethodReport, ParamEstimate, Provenance,
};
pub use crate::machine::dc::{render_text, segment_plots};
pub use crate::machine::im::{render_im_svg, render_im_text, write_im_svg};
pub use plot::{render_segments_svg, write_segments_svg, SegmentPlot, Trace};
