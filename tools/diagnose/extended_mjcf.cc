#include "extended_mjcf.h"

#include <tinyxml2.h>

#include "spml/parse.h"

#include <filesystem>
#include <functional>
#include <stdexcept>

namespace spml::diagnose_detail {
namespace {

namespace fs = std::filesystem;
using tinyxml2::XMLElement;

// Depth-first search for <tag name="name">.
XMLElement* find_named(XMLElement* root, const char* tag, const std::string& name) {
  for (XMLElement* e = root->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const char* n = e->Attribute("name");
    if (std::string(e->Name()) == tag && n && name == n) return e;
    if (XMLElement* hit = find_named(e, tag, name)) return hit;
  }
  return nullptr;
}

// Joints and bodies are defined under <worldbody> only (an <equality><joint name=...> or a
// <sensor> refers to them by the same attribute and must not be edited).
XMLElement* find_in_worldbody(XMLElement* root, const char* tag, const std::string& name) {
  for (XMLElement* w = root->FirstChildElement("worldbody"); w; w = w->NextSiblingElement("worldbody"))
    if (XMLElement* hit = find_named(w, tag, name)) return hit;
  return nullptr;
}

// An XML comment may not hold "--" (a data path with "-->" would end it and inject markup).
std::string comment_text(std::string s) {
  for (size_t at; (at = s.find("--")) != std::string::npos;) s.replace(at, 2, "- -");
  if (!s.empty() && s.back() == '-') s += ' ';
  return s;
}

// A <custom><text> name not yet used in the document: re-diagnosing an extended model must
// not repeat a name MuJoCo requires to be unique.
std::string unique_text_name(XMLElement* custom, const std::string& name) {
  auto used = [&](const std::string& n) {
    for (XMLElement* t = custom->FirstChildElement("text"); t; t = t->NextSiblingElement("text"))
      if (const char* v = t->Attribute("name"); v && n == v) return true;
    return false;
  };
  std::string out = name;
  for (int k = 2; used(out); ++k) out = name + "_" + std::to_string(k);
  return out;
}

void for_each_element(XMLElement* root, const std::function<void(XMLElement*)>& f) {
  for (XMLElement* e = root->FirstChildElement(); e; e = e->NextSiblingElement()) {
    f(e);
    for_each_element(e, f);
  }
}

}  // namespace

std::string write_extended_mjcf(const std::string& model_path, const MjcfEdits& edits, std::vector<std::string>& notes) {
  tinyxml2::XMLDocument doc;
  if (doc.LoadFile(model_path.c_str()) != tinyxml2::XML_SUCCESS)
    throw std::runtime_error(model_path + ": cannot read it as XML: " + std::string(doc.ErrorStr()));
  XMLElement* root = doc.RootElement();
  if (!root || std::string(root->Name()) != "mujoco") throw std::runtime_error(model_path + ": the root element is not <mujoco>");
  const fs::path dir = fs::absolute(fs::path(model_path)).parent_path();
  auto absolute = [&](const char* p) { return fs::path(p).is_absolute() ? std::string(p) : (dir / p).lexically_normal().string(); };

  // Asset folders and includes resolve against the model's folder; make them absolute.
  bool has_meshdir = false, has_texturedir = false;
  for_each_element(root, [&](XMLElement* e) {
    if (std::string(e->Name()) == "compiler")
      for (const char* attr : {"meshdir", "texturedir", "assetdir"})
        if (const char* v = e->Attribute(attr)) {
          e->SetAttribute(attr, absolute(v).c_str());
          has_meshdir |= std::string(attr) != "texturedir";
          has_texturedir |= std::string(attr) != "meshdir";
        }
  });
  for_each_element(root, [&](XMLElement* e) {
    const char* file = e->Attribute("file");
    if (!file) return;
    const std::string tag = e->Name();
    const bool under_dir = (tag == "mesh" || tag == "skin" || tag == "hfield") ? has_meshdir : tag == "texture" ? has_texturedir : false;
    if (!under_dir) e->SetAttribute("file", absolute(file).c_str());
  });

  for (const auto& [joint, attrs] : edits.joint_attributes) {
    XMLElement* e = find_in_worldbody(root, "joint", joint);
    if (!e) {
      notes.push_back("joint '" + joint + "' is not defined in " + model_path + " itself (an included file?): its corrected values are not written");
      continue;
    }
    for (const auto& [attr, value] : attrs) e->SetAttribute(attr.c_str(), exact_text(value).c_str());
  }
  for (const auto& in : edits.inertials) {
    XMLElement* body = find_in_worldbody(root, "body", in.body);
    if (!body) {
      notes.push_back("body '" + in.body + "' is not defined in " + model_path + " itself: its corrected inertial is not written");
      continue;
    }
    while (XMLElement* old = body->FirstChildElement("inertial")) body->DeleteChild(old);
    XMLElement* inertial = doc.NewElement("inertial");
    inertial->SetAttribute("mass", exact_text(in.mass).c_str());
    inertial->SetAttribute("pos", (exact_text(in.pos[0]) + " " + exact_text(in.pos[1]) + " " + exact_text(in.pos[2])).c_str());
    std::string full;
    for (int k = 0; k < 6; ++k) full += (k ? " " : "") + exact_text(in.fullinertia[k]);
    inertial->SetAttribute("fullinertia", full.c_str());
    body->InsertFirstChild(inertial);
  }
  if (!edits.texts.empty()) {
    XMLElement* custom = root->FirstChildElement("custom");
    if (!custom) custom = root->InsertEndChild(doc.NewElement("custom"))->ToElement();
    for (const auto& [name, data] : edits.texts) {
      XMLElement* text = doc.NewElement("text");
      text->SetAttribute("name", unique_text_name(custom, name).c_str());
      text->SetAttribute("data", data.c_str());
      custom->InsertEndChild(text);
    }
  }
  if (!edits.comment.empty()) {
    // After an <?xml ...?> declaration, which must stay first.
    auto* comment = doc.NewComment((" " + comment_text(edits.comment) + " ").c_str());
    if (doc.FirstChild() && doc.FirstChild()->ToDeclaration())
      doc.InsertAfterChild(doc.FirstChild(), comment);
    else
      doc.InsertFirstChild(comment);
  }
  tinyxml2::XMLPrinter printer;
  doc.Print(&printer);
  return printer.CStr();
}

}  // namespace spml::diagnose_detail
