// The MJCF edits that make a model file say what a consistent identification found: every
// fitted body's <inertial pos mass fullinertia>, every fitted joint's armature, damping,
// frictionloss (the Coulomb level) and stiffness, and every changed parameter of a declared
// linear plugin in its own <custom><text> (MjcfEdits::replaced_texts). Tendon terms and offsets
// have no MJCF attribute here: they are named in `notes` when they changed.
#pragma once

#include <string>
#include <vector>

#include "spml/envs/consistent_identification.h"
#include "spml/envs/mjcf_edit.h"

namespace spml {

MjcfEdits identified_model_edits(const MjcfRegressor& reg, const ConsistentIdentification& id, std::vector<std::string>& notes);

}  // namespace spml
