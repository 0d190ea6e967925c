// A small read-only XML element tree built with expat (for .vti headers and XML transfer
// functions). Expat rather than a hand-written parser: it is the parser VTK itself uses for its
// XML formats, it is fuzzed continuously upstream, it limits entity expansion ("billion laughs")
// and never loads external entities, and Debian ships it (libexpat1-dev).
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tfm {

struct XmlElement {
  std::string name;
  std::map<std::string, std::string> attributes;
  std::vector<std::unique_ptr<XmlElement>> children;
  // Byte range of the element's content (between start and end tag) in the parsed text, so large
  // inline data (base64, ASCII numbers) is read in place and never copied by the parser.
  size_t content_begin = 0, content_end = 0;
  int line = 0;  // line of the start tag, for messages

  const std::string* attribute(const std::string& key) const;
  // First child with this name, or nullptr.
  const XmlElement* child(std::string_view child_name) const;
  std::vector<const XmlElement*> children_named(std::string_view child_name) const;
};

// Parses `text`; the root element is returned. Throws std::runtime_error
// "<name>: not well-formed XML (<expat's reason>) at line L" on any error.
std::unique_ptr<XmlElement> parse_xml(std::string_view text, const std::string& name);

// Escapes &, <, >, " and ' for attribute values and text.
std::string xml_escape(std::string_view text);

}  // namespace tfm
