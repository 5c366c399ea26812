//! Training: the run ([`trainer`]: [`prepare`] the folder and data, state, [`epoch`]s of
//! steps, [`run`]'s epoch ends and test, [`lines`] printed) over
//! the trainable models (`infer::detector`), fed by [`loader`]; learning-rate schedule
//! ([`schedule`]), optimisers and global-norm clipping ([`optim`]), weight EMA ([`ema`]),
//! divergence stop ([`divergence`]), f16 loss scaling ([`loss_scale`]; the casts are
//! `infer::precision`), starting weights (`model.init`, [`init`]), the run folder's
//! other files ([`run_files`]) and plots ([`plot`]), self-training on unlabeled photos
//! ([`self_training`]). Checkpoint files, the model
//! wrapper and per-epoch COCO validation are `infer`'s, below it: running a trained
//! model never imports the training loop. The commands built on it live in `commands/`,
//! above it.

pub mod batch_plots;
pub mod divergence;
pub mod ema;
pub mod epoch;
pub mod init;
pub mod interrupt;
pub mod lines;
pub mod loader;
pub mod loss_scale;
pub mod optim;
pub mod plot;
pub mod prepare;
pub mod run;
pub mod run_files;
pub mod run_folder;
pub mod run_plots;
pub mod schedule;
pub mod self_training;
pub mod smoke;
pub mod state;
pub mod trainer;
