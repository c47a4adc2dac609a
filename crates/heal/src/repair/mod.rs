//! Repairs beyond planarity (issue 35): each one named, counted per building and verified like
//! the planarity heal.
