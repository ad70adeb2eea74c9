#include "spml/envs/mjcf_edit.h"

#include <tinyxml2.h>

#include <filesystem>
#include <functional>
#include <stdexcept>

#include "spml/parse.h"

namespace spml {
namespace {

namespace fs = std::filesystem;
using tinyxml2::XMLElement;

void visit(XMLElement* root, const std::function<void(XMLElement*)>& f) {
  for (XMLElement* e = root->FirstChildElement(); e; e = e->NextSiblingElement()) {
    f(e);
    visit(e, f);
  }
}

// Joints and bodies are defined under <worldbody> only: an <equality><joint name=...> or a
// <sensor> refers to them by the same attribute and must not be edited.
XMLElement* defined(XMLElement* root, const std::string& tag, const std::string& name) {
  XMLElement* hit = nullptr;
  for (XMLElement* w = root->FirstChildElement("worldbody"); w && !hit; w = w->NextSiblingElement("worldbody"))
    visit(w, [&](XMLElement* e) {
      const char* n = e->Attribute("name");
      if (!hit && tag == e->Name() && n && name == n) hit = e;
    });
  return hit;
}

// An XML comment may not hold "--" (a data path with "-->" would end it and inject markup).
std::string comment_text(std::string s) {
  for (size_t at; (at = s.find("--")) != std::string::npos;) s.replace(at, 2, "- -");
  if (!s.empty() && s.back() == '-') s += ' ';
  return s;
}

// A <custom><text> name not yet used in the document: editing an already edited model (a
// diagnosis of an extended.xml) must not repeat a name MuJoCo requires to be unique.
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

std::string joined(const double* v, int n) {
  std::string s;
  for (int k = 0; k < n; ++k) s += (k ? " " : "") + exact_text(v[k]);
  return s;
}

// Asset folders, asset files and includes resolve against the model's folder: made absolute.
void absolute_paths(XMLElement* root, const fs::path& dir) {
  auto absolute = [&](const char* p) { return fs::path(p).is_absolute() ? std::string(p) : (dir / p).lexically_normal().string(); };
  bool meshdir = false, texturedir = false;
  visit(root, [&](XMLElement* e) {
    if (std::string(e->Name()) != "compiler") return;
    for (const char* attr : {"meshdir", "texturedir", "assetdir"})
      if (const char* v = e->Attribute(attr)) {
        e->SetAttribute(attr, absolute(v).c_str());
        meshdir |= std::string(attr) != "texturedir";
        texturedir |= std::string(attr) != "meshdir";
      }
  });
  visit(root, [&](XMLElement* e) {
    const char* file = e->Attribute("file");
    if (!file) return;
    const std::string tag = e->Name();
    const bool in_dir = (tag == "mesh" || tag == "skin" || tag == "hfield") ? meshdir : tag == "texture" && texturedir;
    if (!in_dir) e->SetAttribute("file", absolute(file).c_str());
  });
}

void check_compiler(XMLElement* root, const std::string& path) {
  visit(root, [&](XMLElement* e) {
    if (std::string(e->Name()) != "compiler") return;
    const char* fromgeom = e->Attribute("inertiafromgeom");
    if (fromgeom && std::string(fromgeom) == "true")
      throw std::runtime_error(path + ": <compiler inertiafromgeom=\"true\"> would replace the written inertials by the geoms'");
    if (e->DoubleAttribute("settotalmass", -1) > 0)
      throw std::runtime_error(path + ": <compiler settotalmass> would rescale the written masses");
  });
}

void set_inertial(tinyxml2::XMLDocument& doc, XMLElement* body, const MjcfEdits::Inertial& in) {
  while (XMLElement* old = body->FirstChildElement("inertial")) body->DeleteChild(old);
  XMLElement* e = doc.NewElement("inertial");
  e->SetAttribute("pos", joined(in.pos.data(), 3).c_str());
  e->SetAttribute("mass", exact_text(in.mass).c_str());
  e->SetAttribute("fullinertia", joined(in.fullinertia.data(), 6).c_str());
  body->InsertFirstChild(e);
}

XMLElement* load_mujoco(tinyxml2::XMLDocument& doc, const std::string& model_path) {
  if (doc.LoadFile(model_path.c_str()) != tinyxml2::XML_SUCCESS)
    throw std::runtime_error(model_path + ": cannot read it as XML: " + std::string(doc.ErrorStr()));
  XMLElement* root = doc.RootElement();
  if (!root || std::string(root->Name()) != "mujoco") throw std::runtime_error(model_path + ": the root element is not <mujoco>");
  return root;
}

}  // namespace

bool mjcf_angles_in_degrees(const std::string& model_path) {
  tinyxml2::XMLDocument doc;
  bool degrees = true;   // MuJoCo's default
  visit(load_mujoco(doc, model_path), [&](XMLElement* e) {
    const char* angle = std::string(e->Name()) == "compiler" ? e->Attribute("angle") : nullptr;
    if (angle) degrees = std::string(angle) != "radian";
  });
  return degrees;
}

std::vector<std::string> mjcf_defined_joints(const std::string& model_path) {
  tinyxml2::XMLDocument doc;
  XMLElement* root = load_mujoco(doc, model_path);
  std::vector<std::string> out;
  for (XMLElement* w = root->FirstChildElement("worldbody"); w; w = w->NextSiblingElement("worldbody"))
    visit(w, [&](XMLElement* e) {
      const char* n = e->Attribute("name");
      if (n && std::string(e->Name()) == "joint") out.push_back(n);
    });
  return out;
}

std::string edit_mjcf(const std::string& model_path, const MjcfEdits& edits, std::vector<std::string>& notes) {
  tinyxml2::XMLDocument doc;
  XMLElement* root = load_mujoco(doc, model_path);
  if (!edits.inertials.empty()) check_compiler(root, model_path);
  absolute_paths(root, fs::absolute(fs::path(model_path)).parent_path());
  for (const auto& [joint, attrs] : edits.joint_attributes) {
    XMLElement* e = defined(root, "joint", joint);
    if (!e) {
      notes.push_back("joint '" + joint + "' is not defined in " + model_path + " itself (an included file?): its values are not written");
      continue;
    }
    for (const auto& [attr, value] : attrs) e->SetAttribute(attr.c_str(), exact_text(value).c_str());
  }
  for (const auto& in : edits.inertials) {
    XMLElement* body = defined(root, "body", in.body);
    if (body)
      set_inertial(doc, body, in);
    else
      notes.push_back("body '" + in.body + "' is not defined in " + model_path + " itself (unnamed or included?): its inertial is not written");
  }
  for (const auto& [name, data] : edits.replaced_texts) {
    XMLElement* found = nullptr;
    for (XMLElement* custom = root->FirstChildElement("custom"); custom && !found; custom = custom->NextSiblingElement("custom"))
      for (XMLElement* t = custom->FirstChildElement("text"); t && !found; t = t->NextSiblingElement("text"))
        if (const char* v = t->Attribute("name"); v && name == v) found = t;
    if (found)
      found->SetAttribute("data", data.c_str());
    else
      notes.push_back("<custom><text name=\"" + name + "\"> is not in " + model_path + " itself (an included file?): its new data (" + data + ") is not written");
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

}  // namespace spml
