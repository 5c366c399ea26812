//! Training: the run ([`trainer`]: prepare, data, state, epochs, checkpoints, test) over
//! the trainable models ([`detector`]), fed by [`loader`]; learning-rate schedule
//! ([`schedule`]), optimisers and global-norm clipping ([`optim`]), weight EMA ([`ema`]),
//! divergence stop ([`divergence`]), reduced precision ([`precision`], f16 loss scaling
//! in [`loss_scale`]), checkpoint files ([`checkpoint`]), starting weights
//! (`model.init`, [`init`]), the run folder's
//! other files ([`run_files`]), per-epoch COCO evaluation ([`evaluate`]) and plots
//! ([`plot`]). The commands built on it live in `commands/`, above it.

pub mod batch_plots;
pub mod checkpoint;
pub mod detector;
pub mod device;
pub mod divergence;
pub mod ema;
pub mod evaluate;
pub mod init;
pub mod interrupt;
pub mod loader;
pub mod loss_scale;
pub mod optim;
pub mod plot;
pub mod precision;
pub mod run_files;
pub mod run_folder;
pub mod run_plots;
pub mod schedule;
pub mod smoke;
pub mod state;
pub mod trainer;
