#pragma once
// Text into HTML (the reports and contact sheets write their pages by hand).
#include <string>
#include <string_view>

namespace sd {

// `text` safe inside HTML element content and single- or double-quoted attribute values.
inline std::string EscapeHtml(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

}  // namespace sd
