// Writing the extended model: the input MJCF, edited in place as XML (tinyxml2), so that its
// defaults, classes, names and comments survive.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace spml::diagnose_detail {

struct MjcfEdits {
  // joint name -> MJCF attribute (armature, damping, frictionloss, stiffness) -> value
  std::map<std::string, std::map<std::string, double>> joint_attributes;
  struct Inertial {
    std::string body;
    double mass = 0, pos[3] = {0, 0, 0}, fullinertia[6] = {0, 0, 0, 0, 0, 0};   // xx yy zz xy xz yz at the com
  };
  std::vector<Inertial> inertials;
  // <custom><text name=... data=...>: one force-plugin declaration each
  std::vector<std::pair<std::string, std::string>> texts;
  std::string comment;   // put at the top of the file
};

// Returns the text of the edited model. Relative asset and include paths are made absolute, so
// the file loads from any folder. Anything that cannot be applied (a joint defined in an
// included file) is appended to `notes`. Throws std::runtime_error naming the file.
std::string write_extended_mjcf(const std::string& model_path, const MjcfEdits& edits, std::vector<std::string>& notes);

}  // namespace spml::diagnose_detail
