//! Reports for people and programs: JSON per the contract, a text table,
//! SVG plots.

mod im_plot;
mod im_text;
mod overlay;
pub mod plot;
mod text;

pub use crate::contract::{
    unphysical_param, IdentificationReport, MethodReport, ParamEstimate, Provenance,
};
pub use im_plot::{render_im_svg, write_im_svg};
pub use im_text::render_im_text;
pub use overlay::segment_plots;
pub use plot::{render_segments_svg, write_segments_svg, SegmentPlot, Trace};
pub use text::render_text;
