//! The end-to-end tests (worldgen -> map folder -> engine -> pixels), one module per area, in
//! one test binary (one link of the engine and wgpu instead of seven).

mod buildings;
mod camera_path;
mod dem_import;
mod geotiff;
mod geotiff_mosaic;
mod ground;
mod lighting;
mod map_format;
mod objects;
mod paged_world;
mod pages;
mod pm;
mod pm_prefix;
mod render;
mod screen_error;
mod soak;
mod streaming;
mod terrain;
mod texcache;
mod towns;
mod vegetation;
mod vegetation_switch;
mod viewer_prefetch;
mod viewer_xvfb;
