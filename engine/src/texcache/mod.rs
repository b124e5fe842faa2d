//! The texture cache (seed 000): textures live on the GPU only at the resolution the
//! view needs. CPU logic only; `render` applies its plans.
//!
//! - [`mip`]: the MipMapFactor of a texture on an object (the longest texel edge in metres at
//!   full resolution) and from it and the camera the coarsest mip level with no texel over one
//!   pixel on screen.
//! - [`pool`]: slots of power-of-two sizes under a memory budget; per frame the needed level of
//!   every drawn texture, the least visible losing resolution first when the budget is short,
//!   least recently used textures evicted, uploads under a per-frame byte budget; the result is
//!   a [`pool::Plan`] of slot creations, destructions and uploads for the GPU side.
//! - [`upload_cost`]: the measured frame-thread cost of an uploaded byte, which turns the time
//!   left of the streamer's per-frame GPU budget into bytes of texture uploads.

pub mod mip;
pub mod pool;
pub mod upload_cost;
