// XML element tree from expat's callbacks (see xml_tree.h for why expat).
#include "tfmatch/io/xml_tree.h"

#include <limits>
#include <stdexcept>

#include <expat.h>

namespace tfm {
namespace {

struct Builder {
  XML_Parser parser = nullptr;
  std::unique_ptr<XmlElement> root;
  std::vector<XmlElement*> stack;
  std::string error;
};

void XMLCALL on_start(void* user, const XML_Char* name, const XML_Char** attrs) {
  auto* b = static_cast<Builder*>(user);
  auto e = std::make_unique<XmlElement>();
  e->name = name;
  for (size_t i = 0; attrs[i] && attrs[i + 1]; i += 2) e->attributes[attrs[i]] = attrs[i + 1];
  e->line = static_cast<int>(XML_GetCurrentLineNumber(b->parser));
  // The start tag spans [index, index + count); content follows it.
  e->content_begin = static_cast<size_t>(XML_GetCurrentByteIndex(b->parser) + XML_GetCurrentByteCount(b->parser));
  e->content_end = e->content_begin;
  XmlElement* raw = e.get();
  if (b->stack.empty()) b->root = std::move(e);
  else b->stack.back()->children.push_back(std::move(e));
  b->stack.push_back(raw);
}

void XMLCALL on_end(void* user, const XML_Char*) {
  auto* b = static_cast<Builder*>(user);
  XmlElement* e = b->stack.back();
  // For "<a/>" expat reports the end at the start tag itself: the content stays empty.
  const size_t end = static_cast<size_t>(XML_GetCurrentByteIndex(b->parser));
  if (end > e->content_begin) e->content_end = end;
  b->stack.pop_back();
}

}  // namespace

const std::string* XmlElement::attribute(const std::string& key) const {
  auto it = attributes.find(key);
  return it == attributes.end() ? nullptr : &it->second;
}

const XmlElement* XmlElement::child(std::string_view child_name) const {
  for (const auto& c : children)
    if (c->name == child_name) return c.get();
  return nullptr;
}

std::vector<const XmlElement*> XmlElement::children_named(std::string_view child_name) const {
  std::vector<const XmlElement*> out;
  for (const auto& c : children)
    if (c->name == child_name) out.push_back(c.get());
  return out;
}

std::unique_ptr<XmlElement> parse_xml(std::string_view text, const std::string& name) {
  if (text.size() > size_t(std::numeric_limits<int>::max()))
    throw std::runtime_error(name + ": XML part larger than 2 GiB is not supported");
  Builder b;
  b.parser = XML_ParserCreate(nullptr);
  if (!b.parser) throw std::runtime_error(name + ": cannot create an XML parser (out of memory)");
  XML_SetUserData(b.parser, &b);
  XML_SetElementHandler(b.parser, on_start, on_end);
  const XML_Status status = XML_Parse(b.parser, text.data(), static_cast<int>(text.size()), XML_TRUE);
  std::string message;
  if (status != XML_STATUS_OK) {
    message = name + ": not well-formed XML (" + XML_ErrorString(XML_GetErrorCode(b.parser)) + ") at line " +
              std::to_string(XML_GetCurrentLineNumber(b.parser));
  }
  XML_ParserFree(b.parser);
  if (!message.empty()) throw std::runtime_error(message);
  if (!b.root) throw std::runtime_error(name + ": no XML element found");
  return std::move(b.root);
}

std::string xml_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out.push_back(c);
    }
  }
  return out;
}

}  // namespace tfm
