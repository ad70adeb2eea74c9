#include "spml/column_unit.h"

#include <algorithm>

namespace spml {

std::string column_unit(const std::string& column, bool slide) {
  struct Row {
    const char *prefix, *hinge, *slide;
  };
  // Longest prefixes first: "qdd:" also starts with "q".
  static const Row kUnits[] = {{"tau:", "N·m", "N"},          {"force:", "N", "N"},      {"qdd:", "rad/s²", "m/s²"},
                               {"qd:", "rad/s", "m/s"}, {"q:", "rad", "m"}};
  for (const auto& u : kUnits)
    if (column.rfind(u.prefix, 0) == 0) return slide ? u.slide : u.hinge;
  return column == "t" ? "s" : "";
}

std::string column_unit(const std::string& column, const std::vector<std::string>& slide_joints) {
  const auto colon = column.find(':');
  const std::string joint = colon == std::string::npos ? std::string() : column.substr(colon + 1);
  const bool slide = !joint.empty() && std::find(slide_joints.begin(), slide_joints.end(), joint) != slide_joints.end();
  return column_unit(column, slide);
}

}  // namespace spml
