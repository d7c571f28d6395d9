//! A package on disk: its description and its tracks' headers, checked to share one
//! timeline before anything plays.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use vbim_format::package::{Package, WeatherTracks, MAX_PACKAGE_BYTES};
use vbim_format::{Header, Reader, MAGIC, READ_AHEAD_POINTS};

use crate::PlayerError;

/// What a track holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackKind {
    /// A lightmap sequence.
    Lightmap,
    /// The sky over the upper hemisphere (equirectangular, the zenith's row first).
    Sky,
    /// Light for objects: a grid of irradiance (`vbim_format::irradiance`).
    Irradiance,
}

impl TrackKind {
    /// The kind's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            TrackKind::Lightmap => "lightmap",
            TrackKind::Sky => "sky",
            TrackKind::Irradiance => "irradiance",
        }
    }
}

/// One track of a package, as its file's header states it.
#[derive(Clone, Debug)]
pub struct TrackInfo {
    /// Its weather.
    pub weather: String,
    /// What it holds.
    pub kind: TrackKind,
    /// Its file.
    pub path: PathBuf,
    /// Its header.
    pub header: Header,
    /// Its file's size, bytes.
    pub bytes: u64,
}

/// A package on disk: its description and its tracks' headers, checked to share one
/// timeline. [`PackageFile::open`] reads no more than the headers and indexes.
#[derive(Clone, Debug)]
pub struct PackageFile {
    /// The package (for a plain `.vbim` file, a package of one weather).
    pub package: Package,
    /// Every track, weather by weather, the lightmap before the sky.
    pub tracks: Vec<TrackInfo>,
    /// The package file's path.
    pub path: PathBuf,
}

/// An optional track of a weather: what it is, what a switch would lose without it, and
/// whether a weather has it.
type OptionalTrack = (&'static str, &'static str, fn(&WeatherTracks) -> bool);

pub(super) fn package_error(path: &Path, reason: impl ToString) -> PlayerError {
    PlayerError::Package {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

impl PackageFile {
    /// Reads a package file, or a plain `.vbim` file as a package of one weather, and the
    /// header of every track it names. Refuses tracks whose frame counts, rates or loops
    /// differ, lightmaps (or skies) of different sizes, and a package where some weathers
    /// have a sky and others not; every error names the file.
    pub fn open(path: &Path) -> Result<PackageFile, PlayerError> {
        let meta = std::fs::metadata(path).map_err(|e| package_error(path, e))?;
        if !meta.is_file() {
            return Err(package_error(path, "not a regular file"));
        }
        let mut f = File::open(path).map_err(|e| package_error(path, e))?;
        // A `.vbim` file is known by its first 8 bytes; only a package is read whole.
        let mut head = Vec::new();
        (&mut f)
            .take(MAGIC.len() as u64)
            .read_to_end(&mut head)
            .map_err(|e| package_error(path, e))?;
        if !head.starts_with(&MAGIC) {
            (&mut f)
                .take(MAX_PACKAGE_BYTES + 1 - head.len() as u64)
                .read_to_end(&mut head)
                .map_err(|e| package_error(path, e))?;
        }
        let package = if head.starts_with(&MAGIC) {
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .ok_or_else(|| package_error(path, "the file name is not UTF-8"))?;
            Package::single(name)
        } else {
            let text = std::str::from_utf8(&head)
                .map_err(|_| package_error(path, "neither a .vbim file nor a package's JSON"))?;
            Package::parse(text).map_err(|e| package_error(path, e))?
        };
        let base = path.parent().unwrap_or(Path::new(""));
        let mut tracks = Vec::new();
        for w in &package.weathers {
            let kinds = [
                (TrackKind::Lightmap, Some(&w.lightmap)),
                (TrackKind::Sky, w.sky.as_ref()),
                (TrackKind::Irradiance, w.irradiance.as_ref()),
            ];
            for (kind, rel) in kinds {
                let Some(rel) = rel else { continue };
                let path = base.join(rel);
                let file = File::open(&path).map_err(|e| package_error(&path, e))?;
                let bytes = file.metadata().map_err(|e| package_error(&path, e))?.len();
                let reader = Reader::open(file).map_err(|e| package_error(&path, e))?;
                tracks.push(TrackInfo {
                    weather: w.name.clone(),
                    kind,
                    path,
                    header: reader.header().clone(),
                    bytes,
                });
            }
        }
        let p = PackageFile {
            package,
            tracks,
            path: path.to_path_buf(),
        };
        p.check()?;
        Ok(p)
    }

    /// One timeline: the same frames, rate and loop in every track; one size per kind;
    /// a sky in every weather or in none.
    fn check(&self) -> Result<(), PlayerError> {
        let first = &self.tracks[0];
        let timing = |h: &Header| (h.frame_count, h.rate_num, h.rate_den, h.looping);
        for t in &self.tracks {
            if timing(&t.header) != timing(&first.header) {
                return Err(package_error(
                    &t.path,
                    format!(
                        "{} frames at {}/{} fps{}, but {} has {} at {}/{}{}: the tracks of a \
                         package share one timeline",
                        t.header.frame_count,
                        t.header.rate_num,
                        t.header.rate_den,
                        if t.header.looping { ", looping" } else { "" },
                        first.path.display(),
                        first.header.frame_count,
                        first.header.rate_num,
                        first.header.rate_den,
                        if first.header.looping {
                            ", looping"
                        } else {
                            ""
                        },
                    ),
                ));
            }
            let same_kind = self
                .tracks
                .iter()
                .find(|o| o.kind == t.kind)
                .expect("itself");
            let size = |h: &Header| (h.width, h.height);
            if size(&t.header) != size(&same_kind.header) {
                return Err(package_error(
                    &t.path,
                    format!(
                        "a {} track of {}×{}, but {} is {}×{}",
                        t.kind.name(),
                        t.header.width,
                        t.header.height,
                        same_kind.path.display(),
                        same_kind.header.width,
                        same_kind.header.height
                    ),
                ));
            }
        }
        // An optional track in every weather or in none.
        let weathers = &self.package.weathers;
        let optional: [OptionalTrack; 2] = [
            ("a sky track", "the sky", |w| w.sky.is_some()),
            ("an irradiance track", "the light for objects", |w| {
                w.irradiance.is_some()
            }),
        ];
        for (track, lost, has) in optional {
            let n = weathers.iter().filter(|w| has(w)).count();
            if n != 0 && n != weathers.len() {
                return Err(package_error(
                    &self.path,
                    format!(
                        "some weathers have {track} and others not: a switch would lose {lost}"
                    ),
                ));
            }
        }
        for t in self
            .tracks
            .iter()
            .filter(|t| t.kind == TrackKind::Irradiance)
        {
            vbim_format::irradiance::frame_cells(&t.header)
                .map_err(|e| package_error(&t.path, e))?;
        }
        Ok(())
    }

    /// The tracks of weather `name`.
    pub fn weather(&self, name: &str) -> Result<&WeatherTracks, PlayerError> {
        self.package.weather(name).ok_or_else(|| {
            let names: Vec<&str> = self
                .package
                .weathers
                .iter()
                .map(|w| w.name.as_str())
                .collect();
            package_error(
                &self.path,
                format!("no weather {name:?} (it has {})", names.join(", ")),
            )
        })
    }

    /// The buffer model of the tracks of `weathers` read side by side (one weather's
    /// lightmap and sky; two weathers' from a switch to the end of its fade): at each of
    /// the header's points, every track at that multiple of its own mean rate
    /// ([`vbim_format::buffer_model::side_by_side`]).
    pub fn read_ahead(&self, weathers: &[&str]) -> [vbim_format::ReadAhead; READ_AHEAD_POINTS] {
        let tables: Vec<_> = self
            .tracks
            .iter()
            .filter(|t| weathers.contains(&t.weather.as_str()))
            .map(|t| t.header.read_ahead)
            .collect();
        vbim_format::buffer_model::side_by_side(&tables)
    }

    /// A track's info.
    pub(super) fn track(&self, weather: &str, kind: TrackKind) -> Option<&TrackInfo> {
        self.tracks
            .iter()
            .find(|t| t.weather == weather && t.kind == kind)
    }
}
