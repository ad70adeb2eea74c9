// Editing an MJCF file in place as XML (tinyxml2), so that its defaults, classes, names and
// comments survive: new joint attributes, new body inertials, force-plugin declarations.
// The one MJCF writer of spml: `spml identify --write-model` and `spml diagnose`'s extended.xml.
#pragma once

#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace spml {

struct MjcfEdits {
  // joint name -> MJCF attribute (armature, damping, frictionloss, stiffness, springref) -> value, in the
  // file's units (a hinge's springref in degrees where mjcf_angles_in_degrees)
  std::map<std::string, std::map<std::string, double>> joint_attributes;
  struct Inertial {
    std::string body;
    double mass = 0;
    Eigen::Vector3d pos = Eigen::Vector3d::Zero();   // centre of mass, body frame
    std::array<double, 6> fullinertia{};             // Ixx Iyy Izz Ixy Ixz Iyz about the centre of mass
  };
  std::vector<Inertial> inertials;                   // each replaces the body's <inertial>
  std::vector<std::pair<std::string, std::string>> texts;   // <custom><text name data>
  // <custom><text> elements already in the file: name -> its new data (the model's own plugin
  // declarations, e.g. a friction level a diagnosed friction takes over)
  std::map<std::string, std::string> replaced_texts;
  std::string comment;                               // put at the top of the file
};

// The text of the edited model. Relative asset and include paths are made absolute so the file
// loads from any folder. Joints and bodies are looked up under <worldbody> only; a <custom><text>
// name already in the file gets a suffix (_2, _3, ...), while replaced_texts rewrite the data of
// the file's own texts of those names; the comment goes after an <?xml?>
// declaration, with any "--" broken up. What cannot be applied (a joint or body defined in an
// included file, an unnamed body, a replaced text the file does not hold) is appended to `notes`. Throws std::runtime_error naming the file when it is not
// an MJCF or when its compiler settings would override written inertials (inertiafromgeom="true",
// settotalmass).
std::string edit_mjcf(const std::string& model_path, const MjcfEdits& edits, std::vector<std::string>& notes);

// Whether the file's hinge angles (range, ref, springref) are in degrees: MuJoCo's default,
// unless a <compiler angle="radian"> in the file itself says otherwise (an included file's
// compiler is not read). Throws like edit_mjcf when the file is not an MJCF.
bool mjcf_angles_in_degrees(const std::string& model_path);

// The joints the file itself defines under <worldbody> (the ones edit_mjcf can give attributes;
// not those of an included file).
std::vector<std::string> mjcf_defined_joints(const std::string& model_path);

}  // namespace spml
