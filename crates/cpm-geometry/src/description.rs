//! Robot description files (TOML): joint table, sensors, home pose, clearance, load.
