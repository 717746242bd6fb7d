//! What a character cloth's components keep from step to step, as a value
//! a game can save beside the cloth's own [`ClothSnapshot`](crate::ClothSnapshot):
//! [`CharacterSnapshot`].

use bevy::math::{Affine3A, Vec3A};
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::{ClothInertia, ClothSkin, SkinError};

/// What [`ClothSkin`] and [`ClothInertia`] remember of the last step: the
/// skin's pose at its end (where `stiff` moves the skin from through its
/// substeps) and the inertia's anchor transform and its motion over it
/// (what the next step's velocity and acceleration are measured against).
/// Without them a restored cape's first step takes its skin where it is
/// from the first substep and feels none of its anchor's motion: it
/// continues, but not as it would have. With them, and the
/// [`ClothSnapshot`](crate::ClothSnapshot), and the joints and anchor
/// where they were when it was taken, it continues bitwise.
///
/// `Reflect`; with the `serialize` feature serde's too, as `ClothSnapshot`.
#[derive(Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct CharacterSnapshot {
    /// The skin's positions at the last step's end (empty: no skin, or no
    /// step yet).
    pub skin_previous: Vec<[f32; 3]>,
    /// The inertia's anchor transform at the last step and its motion over
    /// that step, each as the 12 floats of an affine map (its three columns
    /// and its translation); `None`: no inertia, or no step yet.
    pub inertia_last: Option<([f32; 12], [f32; 12])>,
}

impl CharacterSnapshot {
    /// Takes what `skin` and `inertia` (either may be absent) remember.
    pub fn of(skin: Option<&ClothSkin>, inertia: Option<&ClothInertia>) -> Self {
        Self {
            skin_previous: skin.map_or_else(Vec::new, |s| {
                s.previous.iter().map(|p| p.to_array()).collect()
            }),
            inertia_last: inertia
                .and_then(|i| i.last)
                .map(|(at, motion)| (at.to_cols_array(), motion.to_cols_array())),
        }
    }

    /// Puts it back into `skin` and `inertia` (either may be absent; what
    /// the snapshot has for an absent one is ignored). A skin list of
    /// another length than the skin's vertices is
    /// [`SkinError::Length`], a value that is not finite
    /// [`SkinError::Pose`]; then nothing is changed.
    pub fn restore(
        &self,
        skin: Option<&mut ClothSkin>,
        inertia: Option<&mut ClothInertia>,
    ) -> Result<(), SkinError> {
        let finite = |v: &[f32]| v.iter().all(|c| c.is_finite());
        if let Some(skin) = &skin {
            let expected = skin.constraints.max_distance.len();
            let got = self.skin_previous.len();
            if got != 0 && got != expected {
                return Err(SkinError::Length { expected, got });
            }
        }
        if !self.skin_previous.iter().all(|p| finite(p))
            || !self
                .inertia_last
                .is_none_or(|(at, motion)| finite(&at) && finite(&motion))
        {
            return Err(SkinError::Pose);
        }
        if let Some(skin) = skin {
            skin.previous = self
                .skin_previous
                .iter()
                .map(|p| Vec3A::from_array(*p))
                .collect();
        }
        if let Some(inertia) = inertia {
            inertia.last = self.inertia_last.map(|(at, motion)| {
                (
                    Affine3A::from_cols_array(&at),
                    Affine3A::from_cols_array(&motion),
                )
            });
        }
        Ok(())
    }
}
