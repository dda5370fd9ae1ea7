//! The golden RV32IMAC + Zcb + Zicsr instruction-set model the lockstep checker compares the RTL
//! with: `soc_model::hart`, re-exported.
pub use soc_model::hart::*;
