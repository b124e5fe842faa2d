//! sRGB transfer functions: worldgen's ([`worldgen::color`]), the one definition the map's
//! texture mip chains and the renderers share.

pub use worldgen::color::{linear_to_srgb, srgb_to_linear};
