//! Is a CRS geographic (degrees)? Heal's tolerances (snap, planarity, `--max-move`) are metres,
//! so a file in degrees is refused with its CRS named rather than "healed" with a 1 mm snap that
//! is ~100 m on the ground. The knowledge of CRS names is `citygml_io::crs`'s, shared with
//! validate, export, citygml2popa3d and the tileset (one representation along the pipeline).
//!
//! # Examples
//! ```
//! use heal::crs::geographic_epsg;
//! assert_eq!(geographic_epsg("urn:ogc:def:crs:EPSG::4979"), Some(4979));
//! assert_eq!(geographic_epsg("http://www.opengis.net/def/crs/EPSG/0/4326"), Some(4326));
//! assert_eq!(geographic_epsg("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::5783"), None);
//! ```

pub use citygml_io::crs::geographic_epsg;
