//! Packages: several `.vbim` tracks on one timeline, tied by a small JSON file
//! (`docs/FORMAT.md`, "Packages"). A package names its weathers; each weather has a
//! lightmap track and, optionally, a sky track. Every track is an ordinary `.vbim` file with
//! the same frame count, rate and loop point, so each is read, checked and seeked alone and
//! a player reads only the tracks it shows.
//!
//! A plain `.vbim` file is a package of one weather ([`Package::single`]): whatever can play
//! a package plays every older file unchanged.
//!
//! This module only parses and checks the text: paths are relative to the package file's
//! folder and never leave it (no absolute paths, no `..`), so a package cannot point a
//! player at a file outside its own folder.

use serde::{Deserialize, Serialize};

/// The package version this reader writes and reads.
pub const PACKAGE_VERSION: u32 = 1;
/// At most this many weathers in a package.
pub const MAX_WEATHERS: usize = 64;
/// A package file larger than this is refused before it is parsed.
pub const MAX_PACKAGE_BYTES: u64 = 1 << 20;
/// The weather name a single `.vbim` file plays as.
pub const SINGLE_WEATHER: &str = "default";

/// A package: its version and its weathers, in the order the author gave them.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Package {
    /// [`PACKAGE_VERSION`].
    pub vbim_package: u32,
    /// The weathers; the first is shown when none is asked for.
    pub weathers: Vec<WeatherTracks>,
}

/// One weather's tracks, as paths relative to the package file's folder.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WeatherTracks {
    /// The weather's name (letters, digits, `-`, `_`; 1 to 64 characters).
    pub name: String,
    /// The lightmap track.
    pub lightmap: String,
    /// The sky track, if the weather has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sky: Option<String>,
    /// The irradiance track (light for objects, [`crate::irradiance`]), if it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub irradiance: Option<String>,
}

impl WeatherTracks {
    /// The weather's tracks as (kind, path): `"lightmap"`, then `"sky"` and `"irradiance"`
    /// where it has them. A bake's package and the package [`Package::coded_as`] makes of
    /// it give the same kinds in the same order.
    pub fn tracks(&self) -> impl Iterator<Item = (&'static str, &str)> {
        std::iter::once(("lightmap", self.lightmap.as_str()))
            .chain(self.sky.as_deref().map(|p| ("sky", p)))
            .chain(self.irradiance.as_deref().map(|p| ("irradiance", p)))
    }
}

/// What is wrong with a package's text.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PackageError {
    /// Not JSON of a package's shape.
    #[error("not a vbim package: {0}")]
    Syntax(String),
    /// A version this reader does not know.
    #[error("package version {0} (this reader knows {PACKAGE_VERSION})")]
    Version(u32),
    /// A field out of range.
    #[error("{0}")]
    Invalid(String),
}

/// Whether `name` may name a weather (it names files and folders).
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// Whether `path` is a relative path inside the package's folder: `/`-separated parts,
/// none empty, `.` or `..`, no drive or root, at most 255 bytes.
pub fn valid_track_path(path: &str) -> bool {
    !path.is_empty()
        && path.len() <= 255
        && !path.contains('\\')
        && !path.contains(':')
        && !path.contains('\0')
        && path
            .split('/')
            .all(|part| !part.is_empty() && part != "." && part != "..")
}

impl Package {
    /// The package a single `.vbim` file at `file_name` (relative) plays as.
    pub fn single(file_name: &str) -> Package {
        Package {
            vbim_package: PACKAGE_VERSION,
            weathers: vec![WeatherTracks {
                name: SINGLE_WEATHER.into(),
                lightmap: file_name.into(),
                sky: None,
                irradiance: None,
            }],
        }
    }

    /// Parses and checks a package's JSON text.
    pub fn parse(text: &str) -> Result<Package, PackageError> {
        if text.len() as u64 > MAX_PACKAGE_BYTES {
            return Err(PackageError::Invalid(format!(
                "{} bytes (a package is at most {MAX_PACKAGE_BYTES})",
                text.len()
            )));
        }
        let p: Package =
            serde_json::from_str(text).map_err(|e| PackageError::Syntax(e.to_string()))?;
        p.check()?;
        Ok(p)
    }

    /// Checks the version, the names and the paths.
    pub fn check(&self) -> Result<(), PackageError> {
        if self.vbim_package != PACKAGE_VERSION {
            return Err(PackageError::Version(self.vbim_package));
        }
        if self.weathers.is_empty() || self.weathers.len() > MAX_WEATHERS {
            return Err(PackageError::Invalid(format!(
                "{} weathers (1 to {MAX_WEATHERS})",
                self.weathers.len()
            )));
        }
        for (i, w) in self.weathers.iter().enumerate() {
            if !valid_name(&w.name) {
                return Err(PackageError::Invalid(format!(
                    "weather {}: name {:?} (1 to 64 letters, digits, '-' or '_')",
                    i + 1,
                    w.name
                )));
            }
            if self.weathers[..i].iter().any(|o| o.name == w.name) {
                return Err(PackageError::Invalid(format!(
                    "weather {:?} is named twice",
                    w.name
                )));
            }
            for path in std::iter::once(&w.lightmap)
                .chain(&w.sky)
                .chain(&w.irradiance)
            {
                if !valid_track_path(path) {
                    return Err(PackageError::Invalid(format!(
                        "weather {:?}: track path {path:?} (a relative path inside the \
                         package's folder, without '..')",
                        w.name
                    )));
                }
            }
        }
        Ok(())
    }

    /// The weather called `name`.
    pub fn weather(&self, name: &str) -> Option<&WeatherTracks> {
        self.weathers.iter().find(|w| w.name == name)
    }

    /// The package of coded tracks that this one's tracks (a bake's folders of frames)
    /// become when each is coded into a file beside a package called `stem`.vbimpkg:
    /// weather NAME's lightmap in `stem-NAME.vbim`, its sky in `stem-NAME-sky.vbim`, its
    /// irradiance in `stem-NAME-irradiance.vbim`. Every
    /// tool that codes a bake of weathers (`vbim encode`, `vbim demo`, the Bevy example)
    /// names its files so; it codes `self`'s folders into the returned package's files
    /// (weather by weather, in the same order) and writes the package last.
    pub fn coded_as(&self, stem: &str) -> Package {
        Package {
            vbim_package: PACKAGE_VERSION,
            weathers: self
                .weathers
                .iter()
                .map(|w| WeatherTracks {
                    name: w.name.clone(),
                    lightmap: format!("{stem}-{}.vbim", w.name),
                    sky: w
                        .sky
                        .as_ref()
                        .map(|_| format!("{stem}-{}-sky.vbim", w.name)),
                    irradiance: w
                        .irradiance
                        .as_ref()
                        .map(|_| format!("{stem}-{}-irradiance.vbim", w.name)),
                })
                .collect(),
        }
    }

    /// The package as JSON text, as [`Package::parse`] reads it.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a package serialises") + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bake_of_folders_is_coded_into_files_named_after_the_package() {
        let baked = Package {
            vbim_package: 1,
            weathers: vec![
                WeatherTracks {
                    name: "clear".into(),
                    lightmap: "clear".into(),
                    sky: Some("clear/sky".into()),
                    irradiance: None,
                },
                WeatherTracks {
                    name: "night".into(),
                    lightmap: "night".into(),
                    sky: None,
                    irradiance: None,
                },
            ],
        };
        let coded = baked.coded_as("day");
        assert_eq!(coded.weathers[0].lightmap, "day-clear.vbim");
        assert_eq!(coded.weathers[0].sky.as_deref(), Some("day-clear-sky.vbim"));
        assert_eq!(coded.weathers[1].lightmap, "day-night.vbim");
        assert_eq!(coded.weathers[1].sky, None);
        assert_eq!(coded.weathers.len(), 2);
        assert!(Package::parse(&coded.to_json()).is_ok());
    }

    fn two() -> Package {
        Package {
            vbim_package: 1,
            weathers: vec![
                WeatherTracks {
                    name: "clear".into(),
                    lightmap: "day-clear.vbim".into(),
                    sky: Some("day-clear-sky.vbim".into()),
                    irradiance: None,
                },
                WeatherTracks {
                    name: "overcast".into(),
                    lightmap: "tracks/day-overcast.vbim".into(),
                    sky: None,
                    irradiance: None,
                },
            ],
        }
    }

    #[test]
    fn a_package_round_trips_and_names_its_weathers() {
        let p = two();
        assert_eq!(Package::parse(&p.to_json()).unwrap(), p);
        assert_eq!(p.weather("overcast").unwrap().sky, None);
        assert!(p.weather("rain").is_none());
        let one = Package::single("old.vbim");
        assert_eq!(one.weathers[0].name, SINGLE_WEATHER);
        one.check().unwrap();
    }

    #[test]
    fn bad_packages_are_refused_with_what_is_wrong() {
        let with = |f: &dyn Fn(&mut Package)| {
            let mut p = two();
            f(&mut p);
            Package::parse(&p.to_json()).unwrap_err().to_string()
        };
        assert!(with(&|p| p.vbim_package = 2).contains("version 2"));
        assert!(with(&|p| p.weathers.clear()).contains("0 weathers"));
        assert!(with(&|p| p.weathers[1].name = "clear".into()).contains("twice"));
        assert!(with(&|p| p.weathers[0].name = "a b".into()).contains("name"));
        for bad in [
            "../x.vbim",
            "/etc/x.vbim",
            "a//b.vbim",
            "./x.vbim",
            "c:x.vbim",
            "a\\b",
        ] {
            let e = with(&|p| p.weathers[0].lightmap = bad.into());
            assert!(e.contains("track path"), "{bad}: {e}");
        }
        let e = with(&|p| p.weathers[1].sky = Some("..".into()));
        assert!(e.contains("track path"), "{e}");
        assert!(Package::parse("{\"vbim_package\": 1}").is_err());
        assert!(Package::parse("[1, 2]").is_err());
        assert!(Package::parse(&" ".repeat(2 << 20))
            .unwrap_err()
            .to_string()
            .contains("bytes"));
        let extra = two().to_json().replacen('{', "{\"other\": 1,", 1);
        assert!(
            Package::parse(&extra).is_err(),
            "unknown fields are refused"
        );
    }
}
