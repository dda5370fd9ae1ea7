//! RV32IMAC + Zcb + Zicsr instruction encoders (`soc_model::isa`), re-exported for the tests
//! and tools.
pub use soc_model::isa::*;
