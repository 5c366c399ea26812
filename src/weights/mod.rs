//! Weight files of other frameworks, read and written on the host without Python: a
//! PyTorch `.pt` / `.pth` ([`pytorch`]: the `torch.save` zip, its pickle run by
//! [`pickle`] over [`pickle_value`]s, torch's rebuild calls in [`torch_rebuild`], storages
//! and views in [`torch_storage`], a pickled module walked in [`torch_module`]),
//! safetensors ([`safetensors`]), and the one entry point that reads either as a state
//! dict of [`host`] tensors ([`state_dict`]).
//!
//! Foundation layer: it imports only `util`, and builds without the `train` feature so
//! the fuzz targets reach it. Mapping names onto a Burn model is the model layer's
//! (`model::weights` and the key maps beside each family).

pub mod host;
pub mod pickle;
pub mod pickle_value;
pub mod pytorch;
pub mod safetensors;
pub mod state_dict;
pub mod torch_module;
pub mod torch_rebuild;
pub mod torch_storage;
