//! What a model file is, checked as core loads it: the container (magic, versions, sizes, CRC-32C) and the kind's
//! own validation (body model, joint forest, shape model). `supine info` lists files with it, `supine run
//! --check-config` refuses a config whose model files fail it. Runs at start-up only.

use supine_core::model_file::{self, Tag};
use supine_core::{body_model, forest, shape};

/// The outcome of checking one file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModelCheck {
    /// Not a supine model file at all (no magic).
    NotAModel,
    /// A supine model file of a kind this build does not know.
    UnknownKind(String),
    /// A valid model of `kind`, described.
    Valid {
        /// Kind tag.
        kind: Tag,
        /// One line for people: kind, version and size.
        what: String,
    },
    /// A model of `kind` that does not validate.
    Invalid {
        /// Kind tag.
        kind: Tag,
        /// Why, as core says it.
        error: String,
    },
}

/// The name people know a kind by (`body`, `joint forest`, `shape`), or the tag itself.
pub fn kind_name(kind: Tag) -> String {
    match kind {
        body_model::KIND => "body".into(),
        forest::model::KIND => "joint forest".into(),
        shape::KIND => "shape".into(),
        other => String::from_utf8_lossy(&other).into_owned(),
    }
}

/// Check `bytes` as core would load them.
pub fn check(bytes: &[u8]) -> ModelCheck {
    if bytes.get(..8) != Some(&model_file::MAGIC[..]) {
        return ModelCheck::NotAModel;
    }
    let mut kind: Tag = [0; 4];
    kind.copy_from_slice(bytes.get(12..16).unwrap_or(&[0; 4]));
    let result = match kind {
        body_model::KIND => body_model::BodyModelView::parse(bytes).map(|v| {
            format!(
                "body model v{}, {} vertices, valid",
                body_model::FORMAT_VERSION,
                v.vertex_count()
            )
        }),
        forest::model::KIND => forest::model::ForestView::parse(bytes).map(|v| {
            format!(
                "joint forest v{}, {} nodes, {} leaves, valid",
                forest::model::VERSION,
                v.node_count(),
                v.leaf_count()
            )
        }),
        shape::KIND => shape::ShapeModelView::parse(bytes).map(|v| {
            format!(
                "shape model v{}, {}-pixel canonical view, valid",
                shape::FORMAT_VERSION,
                v.pixels()
            )
        }),
        _ => return ModelCheck::UnknownKind(String::from_utf8_lossy(&kind).into_owned()),
    };
    match result {
        Ok(what) => ModelCheck::Valid { kind, what },
        Err(e) => ModelCheck::Invalid {
            kind,
            error: e.to_string(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_are_recognised_and_damage_is_reported() {
        assert_eq!(check(b"hello"), ModelCheck::NotAModel);
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artifacts");
        for (file, kind) in [
            ("body.sbm", body_model::KIND),
            ("joints.jfor", forest::model::KIND),
            ("shape.ssm", shape::KIND),
        ] {
            let mut bytes = std::fs::read(dir.join(file)).unwrap();
            assert!(
                matches!(check(&bytes), ModelCheck::Valid { kind: k, .. } if k == kind),
                "{file}"
            );
            let last = bytes.len() - 1;
            bytes[last] ^= 1;
            assert!(
                matches!(check(&bytes), ModelCheck::Invalid { kind: k, .. } if k == kind),
                "{file}"
            );
        }
    }
}
