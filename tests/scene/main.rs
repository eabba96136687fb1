//! The scene crate from outside: dataset formats written by the synthetic writers (or by hand,
//! from each format's own definition) loaded and validated back, archives unpacked, masks and
//! frame images read for the engine, and the real figurine capture when it is present.
//!
//! - [`formats`]: COLMAP (text and binary), nerfstudio and Blender, and their errors;
//! - [`lenses`]: distorted cameras undistorted to the engine's pinhole;
//! - [`dynamic`], [`nerfies`], [`neu3d`]: the dynamic-scene formats and their times;
//! - [`masks_images`]: user masks and frame images;
//! - [`archive`] and [`upload_pipeline`]: archive unpacking, and an archive in, a validated
//!   scene out (what the upload endpoint does, without HTTP);
//! - [`real_data`]: the figurine, where `../shared` or `SEGSPLAT_FIGURINE_DIR` has it.
//!
//! `scene_jpeg_scaled` stays a binary of its own: it installs a counting global allocator.

#[path = "../common/zip_bomb.rs"]
mod zip_bomb;

mod archive;
mod dynamic;
mod formats;
mod lenses;
mod masks_images;
mod nerfies;
mod neu3d;
mod real_data;
mod support;
mod upload_pipeline;
