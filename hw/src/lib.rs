pub mod led;
