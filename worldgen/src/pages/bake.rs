//! Baking a map's raster layers into page files, all pages or any subset.
//!
//! The bake writes into `pages/.<layer>.pages.partial` beside the map's files; a page is a pure
//! function of the layer and its index ([`super::file`]), so any set of bakes that together
//! cover every page, in any order and on any machines sharing the folder, leaves the same bytes.
//! [`finish`] then reads every page back (mark and checksum) and renames each file to
//! `pages/<layer>.pages`. An interrupted bake, or one that ran out of disk, leaves only partial
//! files, which no reader opens.
//!
//! Layers, named by their files in the map: the heights (f32 metres, `pages/heights.exr.pages`),
//! the ground types (u8) and each species' density (u8).

use super::file::{PageLayout, PageWriter, Sample};
use super::{DEFAULT_PAGE_SIDE, PageError, PageFile, SampleKind};
use crate::progress::Progress;
use crate::{Grid, Map};
use std::path::{Path, PathBuf};

/// The folder of a map's page files.
pub fn pages_dir(map_dir: &Path) -> PathBuf {
    map_dir.join("pages")
}

/// The finished page file of `layer`.
pub fn page_file_path(map_dir: &Path, layer: &str) -> PathBuf {
    pages_dir(map_dir).join(format!("{layer}.pages"))
}

fn partial_path(map_dir: &Path, layer: &str) -> PathBuf {
    pages_dir(map_dir).join(format!(".{layer}.pages.partial"))
}

/// One raster layer of a map.
#[derive(Clone, Copy, Debug)]
pub enum Raster<'a> {
    F32(&'a Grid<f32>),
    U8(&'a Grid<u8>),
}

impl Raster<'_> {
    fn size(&self) -> (usize, usize) {
        match self {
            Raster::F32(g) => (g.width(), g.height()),
            Raster::U8(g) => (g.width(), g.height()),
        }
    }

    fn kind(&self) -> super::SampleKind {
        match self {
            Raster::F32(_) => f32::KIND,
            Raster::U8(_) => u8::KIND,
        }
    }

    /// A [`super::SourceKey`] of the layer's size and samples.
    pub fn key(&self) -> u64 {
        let (w, h) = self.size();
        let mut key = super::SourceKey::new(0x5EED_0000);
        key.update(&(w as u64).to_le_bytes());
        key.update(&(h as u64).to_le_bytes());
        match self {
            Raster::F32(g) => {
                for row in g.data().chunks(4096) {
                    let bytes: Vec<u8> = row.iter().flat_map(|v| v.to_le_bytes()).collect();
                    key.update(&bytes);
                }
            }
            Raster::U8(g) => key.update(g.data()),
        }
        key.finish()
    }

    fn layout(&self, page_side: u32) -> Result<PageLayout, String> {
        let (w, h) = self.size();
        PageLayout::new(self.kind(), w as u32, h as u32, page_side)
    }
}

/// The map's raster layers, named by their files in the map (unique, checked names), in the
/// manifest's order: heights, ground types, then the species' densities. The map must hold
/// its layers in memory (a bake reads a map loaded by [`Map::load`], not served from pages).
pub fn rasters(map: &Map) -> Result<Vec<(String, Raster<'_>)>, PageError> {
    let m = &map.manifest;
    let whole = |file: &str| PageError::Request {
        path: PathBuf::from(file),
        problem: "the layer is served from pages; a bake reads a map loaded whole".into(),
    };
    let heights = map.heights.grid().ok_or_else(|| whole(&m.heights.file))?;
    let ground = map.ground.grid().ok_or_else(|| whole(&m.ground.file))?;
    let mut out = vec![
        (m.heights.file.clone(), Raster::F32(heights)),
        (m.ground.file.clone(), Raster::U8(ground)),
    ];
    for d in &map.densities {
        out.push((d.spec.file.clone(), Raster::U8(&d.density)));
    }
    Ok(out)
}

/// Which pages of each layer a bake writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PageSet {
    All,
    /// Pages whose index `i` has `i % count == part` (one of `count` equal shares).
    Share {
        part: u32,
        count: u32,
    },
    /// These page indices (those past a layer's last page are ignored).
    Indices(Vec<u32>),
}

impl PageSet {
    pub fn contains(&self, index: u32) -> bool {
        match self {
            PageSet::All => true,
            PageSet::Share { part, count } => index % count == *part,
            PageSet::Indices(list) => list.contains(&index),
        }
    }
}

/// What a bake wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BakeReport {
    pub pages_written: u64,
    pub bytes_written: u64,
}

/// Writes the pages of `set` of every raster layer of `map` (stored in `map_dir`) into the
/// layers' partial files, creating them where needed.
pub fn bake(
    map: &Map,
    map_dir: &Path,
    page_side: u32,
    set: &PageSet,
    progress: &dyn Progress,
) -> Result<BakeReport, PageError> {
    let dir = pages_dir(map_dir);
    std::fs::create_dir_all(&dir).map_err(|source| PageError::Io {
        path: dir.clone(),
        action: "create the pages folder",
        source,
    })?;
    let layers = rasters(map)?;
    let mut jobs = Vec::new();
    for (name, raster) in &layers {
        let path = partial_path(map_dir, name);
        let layout = raster
            .layout(page_side)
            .map_err(|problem| PageError::Request {
                path: path.clone(),
                problem,
            })?;
        let writer = PageWriter::create_or_continue(&path, layout, raster.key())?;
        let pages: Vec<u32> = (0..layout.page_count())
            .filter(|&i| set.contains(i))
            .collect();
        jobs.push((writer, *raster, pages));
    }
    let total: u64 = jobs.iter().map(|j| j.2.len() as u64).sum();
    progress.begin("bake pages", total);
    let mut report = BakeReport::default();
    for (writer, raster, pages) in &jobs {
        let layout = writer.layout();
        for &index in pages {
            let (column, row) = layout.column_row(index);
            match raster {
                Raster::F32(g) => writer.write_page(g, column, row)?,
                Raster::U8(g) => writer.write_page(g, column, row)?,
            }
            report.pages_written += 1;
            report.bytes_written += layout.page_stride_bytes();
            progress.advance(1);
        }
        writer.sync()?;
    }
    progress.end();
    Ok(report)
}

/// Pages of each started layer not baked yet: (layer, page indices). A layer with no partial
/// file and no finished file is listed by [`finish`] as not started.
pub fn missing_pages(map: &Map, map_dir: &Path) -> Result<Vec<(String, Vec<u32>)>, PageError> {
    let mut out = Vec::new();
    for (name, _) in rasters(map)? {
        let path = partial_path(map_dir, &name);
        if !path.exists() {
            continue;
        }
        let file = PageFile::open(&path)?;
        let mut missing = Vec::new();
        for i in 0..file.layout().page_count() {
            if !file.is_baked(i)? {
                missing.push(i);
            }
        }
        if !missing.is_empty() {
            out.push((name, missing));
        }
    }
    Ok(out)
}

/// Opens `path` and checks that it was baked from `raster` (`name` in messages).
fn open_checked(path: PathBuf, name: &str, raster: &Raster<'_>) -> Result<PageFile, PageError> {
    let file = PageFile::open(&path)?;
    if file.key() != raster.key() {
        return Err(PageError::Header {
            path,
            problem: format!("baked from another `{name}` layer than this map's; bake it again"),
        });
    }
    Ok(file)
}

/// Reads every page of `files` (mark and checksum), one unit of `progress` per page.
fn read_every_page(files: &[(String, PageFile)], progress: &dyn Progress) -> Result<(), PageError> {
    let total = files
        .iter()
        .map(|(_, f)| u64::from(f.layout().page_count()))
        .sum();
    progress.begin("check pages", total);
    for (_, file) in files {
        let l = file.layout();
        for i in 0..l.page_count() {
            let (column, row) = l.column_row(i);
            match l.kind {
                super::SampleKind::F32 => file.read_page::<f32>(column, row).map(drop)?,
                super::SampleKind::U8 => file.read_page::<u8>(column, row).map(drop)?,
            }
            progress.advance(1);
        }
    }
    progress.end();
    Ok(())
}

/// Checks every page of every partial file of `map` (mark and checksum, and that the file was
/// baked from this map's layer) and renames the files into place. Fails, renaming nothing, when
/// a page is missing or damaged.
pub fn finish(map: &Map, map_dir: &Path, progress: &dyn Progress) -> Result<usize, PageError> {
    let mut ready = Vec::new();
    for (name, raster) in &rasters(map)? {
        let path = partial_path(map_dir, name);
        if !path.exists() {
            if page_file_path(map_dir, name).exists() {
                continue;
            }
            return Err(PageError::Request {
                path,
                problem: format!(
                    "no bake of layer `{name}` was started; run `worldgen bake` first"
                ),
            });
        }
        ready.push((name.clone(), open_checked(path, name, raster)?));
    }
    read_every_page(&ready, progress)?;
    for (name, file) in &ready {
        let to = page_file_path(map_dir, name);
        std::fs::rename(file.path(), &to).map_err(|source| PageError::Io {
            path: to.clone(),
            action: "move the finished page file into place",
            source,
        })?;
    }
    write_sources(map, map_dir)?;
    Ok(ready.len())
}

/// Writes the decal and tree lists in binary and the record of the bake's sources
/// ([`super::sources`]): the files an open then reads from the bake instead.
fn write_sources(map: &Map, map_dir: &Path) -> Result<(), PageError> {
    let mut baked: Vec<(String, u64)> = rasters(map)?
        .iter()
        .map(|(name, raster)| (name.clone(), raster.key()))
        .collect();
    let decals_key = super::decal_list::write(&super::decal_list::path(map_dir), &map.decals)?;
    baked.push((map.manifest.decals.file.clone(), decals_key));
    let trees_key = super::tree_list::write(&super::tree_list::path(map_dir), &map.trees)?;
    baked.push((map.manifest.trees.file.clone(), trees_key));
    super::sources::Sources::write(map_dir, &baked)
}

/// Checks the finished page files of `map`: every layer has one, baked from this map's layer,
/// and every page reads (mark and checksum). Returns the number of pages.
pub fn verify(map: &Map, map_dir: &Path, progress: &dyn Progress) -> Result<u64, PageError> {
    let mut files = Vec::new();
    for (name, raster) in &rasters(map)? {
        files.push((
            name.clone(),
            open_checked(page_file_path(map_dir, name), name, raster)?,
        ));
    }
    read_every_page(&files, progress)?;
    Ok(files
        .iter()
        .map(|(_, f)| u64::from(f.layout().page_count()))
        .sum())
}

/// Writes `grid` as the page file `path` (through a hidden partial file beside it, renamed when
/// every page is written and flushed): for rasters derived from a map, baked whole.
pub fn write_grid<T: Sample>(
    path: &Path,
    grid: &Grid<T>,
    page_side: u32,
    key: u64,
) -> Result<(), PageError> {
    let io = |action, source| PageError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    let partial = super::fresh_partial_path(path)?;
    let layout = PageLayout::new(
        T::KIND,
        grid.width() as u32,
        grid.height() as u32,
        page_side,
    )
    .map_err(|problem| PageError::Request {
        path: path.to_path_buf(),
        problem,
    })?;
    let writer = PageWriter::create_or_continue(&partial, layout, key)?;
    for index in 0..layout.page_count() {
        let (column, row) = layout.column_row(index);
        writer.write_page(grid, column, row)?;
    }
    writer.sync()?;
    std::fs::rename(&partial, path).map_err(|e| io("move the page file into place", e))
}

/// Opens the page file `path` of data derived from a map; refused (naming the file) unless it
/// holds `width` x `height` samples of `kind` and was baked with `key`.
pub fn open_derived(
    path: &Path,
    kind: SampleKind,
    width: usize,
    height: usize,
    key: u64,
) -> Result<PageFile, PageError> {
    let file = PageFile::open(path)?;
    let l = file.layout();
    if file.key() != key
        || l.kind != kind
        || (l.width as usize, l.height as usize) != (width, height)
    {
        return Err(PageError::Header {
            path: path.to_path_buf(),
            problem: format!(
                "baked from another map or another engine (expected {width}x{height} samples of {kind:?} and this map's key); bake the map again"
            ),
        });
    }
    Ok(file)
}

/// Reads the page file `path` whole as a `width` x `height` grid, checked as by
/// [`open_derived`].
pub fn read_grid<T: Sample>(
    path: &Path,
    width: usize,
    height: usize,
    key: u64,
) -> Result<Grid<T>, PageError> {
    open_derived(path, T::KIND, width, height, key)?.read_all()
}

/// Bakes every page of `map` and finishes: the whole bake on one machine.
pub fn bake_all(
    map: &Map,
    map_dir: &Path,
    progress: &dyn Progress,
) -> Result<BakeReport, PageError> {
    let report = bake(map, map_dir, DEFAULT_PAGE_SIDE, &PageSet::All, progress)?;
    finish(map, map_dir, progress)?;
    Ok(report)
}
