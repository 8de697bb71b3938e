//! `Relight`: one image relit by a job's newest checkpoint (a trained or an adapted model).

use std::path::Path;

use lightfarm_proto::v1 as pb;
use tonic::Status;

use super::{internal, TrainerService};
use crate::image_io::{gray_png_bytes, load_portrait, png_bytes};
use crate::infer::{load_model, normal_colours};
use crate::lights::{identity_camera, Lighting};
use crate::TrainError;

impl TrainerService {
    pub(super) fn relight_blocking(
        &self,
        run: &Path,
        r: pb::RelightRequest,
    ) -> Result<pb::RelightResponse, Status> {
        let bad = |e: TrainError| Status::invalid_argument(e.to_string());
        let tmp = tempfile::tempdir().map_err(internal)?;
        let image = tmp.path().join("image");
        std::fs::write(&image, &r.image).map_err(internal)?;
        let mask = if r.mask.is_empty() {
            None
        } else {
            let m = tmp.path().join("mask");
            std::fs::write(&m, &r.mask).map_err(internal)?;
            Some(m)
        };
        let lighting = match r.lighting {
            Some(pb::relight_request::Lighting::HdriId(id)) => {
                let asset = self
                    .0
                    .cfg
                    .catalog
                    .get(&id)
                    .filter(|a| a.kind == lightfarm_scene::AssetKind::Hdri)
                    .ok_or_else(|| {
                        Status::invalid_argument(format!(
                            "hdri_id '{id}' is not an HDRI of the trainer's catalog"
                        ))
                    })?;
                Lighting::load(&self.0.cfg.catalog.path_of(asset)).map_err(bad)?
            }
            Some(pb::relight_request::Lighting::HdriFile(bytes)) => {
                let ext = if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
                    "exr"
                } else {
                    "hdr"
                };
                let p = tmp.path().join(format!("env.{ext}"));
                std::fs::write(&p, &bytes).map_err(internal)?;
                Lighting::load(&p).map_err(bad)?
            }
            None => return Err(Status::invalid_argument("give hdri_id or hdri_file")),
        };
        let model = load_model(run, &self.0.cfg.device).map_err(internal)?;
        let matte = (!r.no_matte).then_some(&self.0.matting);
        let p = load_portrait(&image, mask.as_deref(), matte).map_err(|e| match e {
            // The trainer's installation lacks MODNet: not the caller's input.
            TrainError::Photo(lightfarm_photo::PhotoError::Model { .. }) => {
                Status::failed_precondition(e.to_string())
            }
            e => bad(e),
        })?;
        let rot = identity_camera(r.rotation_deg, r.flip);
        let (w, h) = (p.width, p.height);
        let out = model
            .relight(&p.rgb, &p.mask, w, h, &lighting, rot)
            .map_err(internal)?;
        let relit = out.with_inset(&lighting, rot);
        let png = |rgb: &[[f32; 3]]| png_bytes(w, h, rgb).map_err(internal);
        Ok(pb::RelightResponse {
            width: w as u32,
            height: h as u32,
            relit_png: png(&relit)?,
            normal_png: png(&normal_colours(&out.normal))?,
            albedo_png: png(&out.albedo)?,
            diffuse_png: png(&out.diffuse)?,
            specular_png: png(&out.specular)?,
            mask_png: gray_png_bytes(w, h, &p.mask).map_err(internal)?,
            matted: p.matted,
        })
    }
}
