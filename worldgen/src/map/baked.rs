//! Reading a baked map's raster layers from their page files and its decal and tree lists from
//! their binary copies, where the record of the bake's sources ([`crate::pages::sources`]) says the
//! map's own files still hold what was baked. Anything missing, stale or damaged is logged and
//! read from the map's own files instead, so a bake only ever makes an open faster.

use super::GridSpec;
use super::lists::{Decal, Tree};
use crate::Grid;
use crate::pages::file::Sample;
use crate::pages::sources::Sources;
use crate::pages::{PageFile, bake, decal_list, tree_list};
use std::path::{Path, PathBuf};

pub(super) struct Baked {
    dir: PathBuf,
    sources: Option<Sources>,
    /// Files read from the bake, for the open's log line.
    pub read: Vec<String>,
}

impl Baked {
    pub fn open(dir: &Path) -> Self {
        Self {
            dir: dir.to_path_buf(),
            sources: Sources::read(dir),
            read: Vec::new(),
        }
    }

    /// The layer of `spec` from its page file, when baked from the layer file as it is now.
    pub fn raster<T: Sample>(&mut self, spec: &GridSpec) -> Option<Grid<T>> {
        let read = self
            .page_file::<T>(spec)?
            .and_then(|file| file.read_all::<T>());
        self.used(&spec.file, read)
    }

    /// The layer of `spec` served from its page file through `paging`, when baked from the
    /// layer file as it is now.
    pub fn paged<T: crate::pages::CacheSample + std::fmt::Debug>(
        &mut self,
        spec: &GridSpec,
        paging: &crate::pages::Paging,
    ) -> Option<crate::pages::PagedRaster<T>> {
        let opened = self
            .page_file::<T>(spec)?
            .and_then(|file| crate::pages::PagedRaster::new(paging, file, T::zero()));
        self.used(&spec.file, opened)
    }

    /// The page file of `spec`'s layer, checked against the record of sources (`None` where
    /// the layer was not baked from its file as it is now) and against `spec`.
    fn page_file<T: Sample>(
        &mut self,
        spec: &GridSpec,
    ) -> Option<Result<PageFile, crate::pages::PageError>> {
        let key = self.sources.as_mut()?.baked_key(&spec.file)?;
        let path = bake::page_file_path(&self.dir, &spec.file);
        let (w, h) = (spec.width as usize, spec.height as usize);
        Some(PageFile::open(&path).and_then(|file| {
            let l = file.layout();
            if file.key() != key
                || l.kind != T::KIND
                || (l.width as usize, l.height as usize) != (w, h)
            {
                return Err(crate::pages::PageError::Header {
                    path: path.clone(),
                    problem: format!(
                        "not the pages of this map's {} ({w}x{h} samples, key {key:016x})",
                        spec.file
                    ),
                });
            }
            Ok(file)
        }))
    }

    /// The decal list from its binary copy, when baked from the text list `name` as it is now.
    pub fn decals(&mut self, name: &str) -> Option<Vec<Decal>> {
        let key = self.sources.as_mut()?.baked_key(name)?;
        let read = decal_list::read(&decal_list::path(&self.dir), key);
        self.used(name, read)
    }

    /// The large trees from their binary copy, when baked from the CSV `name` as it is now.
    pub fn trees(&mut self, name: &str) -> Option<Vec<Tree>> {
        let key = self.sources.as_mut()?.baked_key(name)?;
        let read = tree_list::read(&tree_list::path(&self.dir), key);
        self.used(name, read)
    }

    fn used<T>(&mut self, name: &str, read: Result<T, crate::pages::PageError>) -> Option<T> {
        match read {
            Ok(v) => {
                self.read.push(name.to_string());
                Some(v)
            }
            Err(e) => {
                log::warn!("{e}; {name} is read from the map's own file instead");
                None
            }
        }
    }

    /// Remembers the files checked by content (see [`Sources::save_checked`]).
    pub fn finish(&self) {
        if let Some(s) = &self.sources {
            s.save_checked();
        }
    }
}
