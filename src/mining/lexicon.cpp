#include "mining/lexicon.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "core/error.h"
#include "datasets/categories.h"

namespace sd::mining {
namespace fs = std::filesystem;

namespace {

// Road words WordNet 3.0 lacks or files under another sense (its "pylon" is a tower; it has no traffic cone, no
// warning triangle, no jersey barrier), as users write them in the US, UK and Australia. Phrases in WordNet's form:
// lower case, words joined by '_', apostrophes dropped.
struct RoadWord {
  const char* phrase;
  const char* category;
};
constexpr RoadWord kRoadWords[] = {
    {"cone", "traffic_cone"},           {"pylon", "traffic_cone"},            {"traffic_pylon", "traffic_cone"},
    {"safety_cone", "traffic_cone"},    {"road_cone", "traffic_cone"},        {"witchs_hat", "traffic_cone"},
    {"witches_hat", "traffic_cone"},    {"highway_cone", "traffic_cone"},     {"warning_triangle", "warning_tripod"},
    {"hazard_triangle", "warning_tripod"}, {"breakdown_triangle", "warning_tripod"},
    {"emergency_triangle", "warning_tripod"}, {"reflective_triangle", "warning_tripod"},
    {"red_triangle", "warning_tripod"}, {"safety_triangle", "warning_tripod"}, {"a_frame", "a_frame_sign"},
    {"a-frame", "a_frame_sign"},        {"a-frame_sign", "a_frame_sign"},     {"pavement_sign", "a_frame_sign"},
    {"sidewalk_sign", "a_frame_sign"},  {"road_work_sign", "a_frame_sign"},   {"roadwork_sign", "a_frame_sign"},
    {"construction_sign", "a_frame_sign"}, {"jersey_barrier", "barrier"},     {"k-rail", "barrier"},
    {"k_rail", "barrier"},              {"concrete_barrier", "barrier"},      {"traffic_barrier", "barrier"},
    {"road_barrier", "barrier"},        {"water_barrier", "barrier"},         {"construction_barrier", "barrier"},
    {"temporary_traffic_light", "portable_traffic_light"}, {"temporary_traffic_signal", "portable_traffic_light"},
    {"portable_traffic_signal", "portable_traffic_light"}, {"road_debris", "debris"}, {"lost_cargo", "debris"},
    {"fallen_cargo", "debris"},
};

// Each category's anchor synsets, as WordNet 3.0 lemma and sense number (index.noun's order). A noun that is an
// anchor or lies below one (hypernym chain) names the category.
struct Anchor {
  const char* category;
  const char* lemma;
  int sense;
};
constexpr Anchor kAnchors[] = {
    {"car", "car", 1},
    {"truck", "truck", 1},
    {"trailer", "trailer", 3},              // a transport conveyance pulled by a truck or tractor
    {"trailer", "trailer", 4},              // a house trailer
    {"bus", "bus", 1},
    {"construction_vehicle", "bulldozer", 1},
    {"construction_vehicle", "steamroller", 2},  // road roller
    {"construction_vehicle", "backhoe", 1},
    {"construction_vehicle", "excavator", 2},    // power shovel, digger
    {"construction_vehicle", "cement_mixer", 1},
    {"construction_vehicle", "crane", 4},
    {"construction_vehicle", "forklift", 1},
    {"bicycle", "bicycle", 1},
    {"motorcycle", "motorcycle", 1},
    {"motorcycle", "motor_scooter", 1},     // nuScenes' motorcycle holds scooters and mopeds
    {"pedestrian", "person", 1},
    {"barrier", "crash_barrier", 1},
    {"barrier", "barricade", 1},            // roadblock
    {"barrier", "guardrail", 1},
    {"a_frame_sign", "sandwich_board", 1},
    {"debris", "debris", 1},
    {"portable_traffic_light", "traffic_light", 1},  // the one traffic-light category
};

// How far below a prompt's synset an anchor may lie for the prompt to name its category: "motor vehicle" holds car
// and truck one level down; "vehicle" holds bicycle two levels down, too broad to name it.
constexpr int kMaxBroaderDepth = 1;

// The shortest head word tried within one edit when it is known nowhere.
constexpr size_t kMinEditedLength = 5;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Prompt words in WordNet's form: lower case, apostrophes dropped ("witch's" -> "witchs"), split at anything but
// letters, digits and hyphens.
std::vector<std::string> PromptWords(const std::string& prompt) {
  std::vector<std::string> words;
  std::string w;
  for (char raw : prompt + " ") {
    const char c = static_cast<char>(std::tolower(static_cast<unsigned char>(raw)));
    if (c == '\'') continue;
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '-') {
      w += c;
    } else if (!w.empty()) {
      words.push_back(w);
      w.clear();
    }
  }
  return words;
}

std::string JoinWords(const std::vector<std::string>& words, size_t from, const std::string& sep) {
  std::string s;
  for (size_t i = from; i < words.size(); ++i) s += (i > from ? sep : "") + words[i];
  return s;
}

struct Synset {
  std::vector<std::string> words;
  std::vector<uint32_t> hypernyms, hyponyms;  // '@' / '@i' and '~' / '~i'
  std::string gloss;
};

}  // namespace

fs::path DefaultWordNetDir() {
  if (const char* env = std::getenv("SYNTHDRIVE_WORDNET"); env && *env) return env;
  return "/usr/share/wordnet";
}

struct Lexicon::Impl {
  bool wordnet = false;
  fs::path data_path;
  std::unordered_map<std::string, std::vector<uint32_t>> senses;  // lemma -> synset offsets, sense order
  std::unordered_map<std::string, std::string> exceptions;       // irregular plural -> base
  std::string data;                                               // data.noun
  std::map<uint32_t, std::string> anchor_category;                // synset offset -> category
  mutable std::map<uint32_t, Synset> parsed;                      // filled on demand (not thread-safe: one query at a time)

  const Synset& At(uint32_t offset) const {
    if (auto it = parsed.find(offset); it != parsed.end()) return it->second;
    const auto fail = [&](const std::string& what) {
      return InputError(data_path, Msg() << "synset at byte " << offset << ": " << what);
    };
    if (offset >= data.size()) throw fail("past the end of the file");
    const size_t end = data.find('\n', offset);
    const std::string line = data.substr(offset, end == std::string::npos ? std::string::npos : end - offset);
    const size_t bar = line.find('|');
    std::istringstream in(line.substr(0, bar));
    Synset s;
    uint32_t own = 0;
    std::string lex, type, count_hex;
    if (!(in >> own >> lex >> type >> count_hex) || own != offset || type != "n")
      throw fail("is not a noun synset starting there (the file and index.noun disagree)");
    const unsigned long n_words = std::strtoul(count_hex.c_str(), nullptr, 16);
    for (unsigned long i = 0; i < n_words; ++i) {
      std::string word, lex_id;
      if (!(in >> word >> lex_id)) throw fail("is cut short in its words");
      s.words.push_back(word);  // as written: capitals mark proper nouns
    }
    int n_pointers = 0;
    if (!(in >> n_pointers) || n_pointers < 0) throw fail("has no pointer count");
    for (int i = 0; i < n_pointers; ++i) {
      std::string symbol, pos, source_target;
      uint32_t target = 0;
      if (!(in >> symbol >> target >> pos >> source_target)) throw fail("is cut short in its pointers");
      if (pos != "n") continue;
      if (symbol == "@" || symbol == "@i") s.hypernyms.push_back(target);
      if (symbol == "~" || symbol == "~i") s.hyponyms.push_back(target);
    }
    if (bar != std::string::npos) {
      s.gloss = line.substr(bar + 1);
      s.gloss.erase(0, s.gloss.find_first_not_of(' '));
      s.gloss.erase(s.gloss.find_last_not_of(' ') + 1);
      if (const size_t semi = s.gloss.find(';'); semi != std::string::npos) s.gloss.resize(semi);  // the definition, not the examples
    }
    return parsed.emplace(offset, std::move(s)).first->second;
  }

  bool IsProperNoun(uint32_t offset, const std::string& lemma) const {
    for (const std::string& w : At(offset).words)
      if (Lower(w) == lemma) return std::isupper(static_cast<unsigned char>(w[0])) != 0;
    return false;
  }

  // "lorry#2 (a large truck designed to carry heavy loads)": a synset named by its first word and that word's sense.
  std::string Name(uint32_t offset) const {
    const Synset& s = At(offset);
    const std::string word = s.words.empty() ? std::string("?") : Lower(s.words.front());
    int sense = 0;
    if (auto it = senses.find(word); it != senses.end())
      for (size_t i = 0; i < it->second.size(); ++i)
        if (it->second[i] == offset) sense = static_cast<int>(i) + 1;
    std::string name = word;
    std::replace(name.begin(), name.end(), '_', ' ');
    return name + "#" + std::to_string(sense) + " (" + s.gloss + ")";
  }

  // WordNet's morphology for nouns (morphy): the form itself, its exception-list base, and its suffix-rule bases
  // that are lemmas.
  std::vector<std::string> Bases(const std::string& form) const {
    std::vector<std::string> out = {form};
    if (auto it = exceptions.find(form); it != exceptions.end()) out.push_back(it->second);
    static const std::pair<const char*, const char*> kRules[] = {{"s", ""},     {"ses", "s"}, {"xes", "x"}, {"zes", "z"},
                                                                 {"ches", "ch"}, {"shes", "sh"}, {"men", "man"}, {"ies", "y"}};
    for (const auto& [suffix, repl] : kRules) {
      const std::string suf = suffix;
      if (form.size() > suf.size() && form.compare(form.size() - suf.size(), suf.size(), suf) == 0)
        out.push_back(form.substr(0, form.size() - suf.size()) + repl);
    }
    return out;
  }

  // The categories a WordNet lemma names, each with its chain: anchors at or above its synsets, else anchors
  // at most kMaxBroaderDepth below.
  std::vector<CategoryMatch> Relate(const std::string& lemma) const {
    std::map<std::string, CategoryMatch> found;  // by category: the first (shortest, commonest sense) chain
    // A lower-case prompt means the common noun: "pole" is not a Pole, "crane" not Stephen Crane. Proper-noun
    // senses count only for a lemma that has no other.
    std::vector<uint32_t> roots;
    for (uint32_t o : senses.at(lemma))
      if (!IsProperNoun(o, lemma)) roots.push_back(o);
    if (roots.empty()) roots = senses.at(lemma);
    std::string shown = lemma;
    std::replace(shown.begin(), shown.end(), '_', ' ');
    for (uint32_t root : roots) {
      // Up: breadth first over hypernyms, so the nearest anchor is found first.
      std::map<uint32_t, uint32_t> parent = {{root, root}};
      std::deque<uint32_t> queue = {root};
      while (!queue.empty()) {
        const uint32_t s = queue.front();
        queue.pop_front();
        if (auto a = anchor_category.find(s); a != anchor_category.end()) {
          if (found.count(a->second)) continue;
          std::vector<uint32_t> path;
          for (uint32_t p = s;; p = parent.at(p)) {
            path.push_back(p);
            if (p == root) break;
          }
          std::reverse(path.begin(), path.end());
          std::string chain = shown + " = " + Name(path.front());
          for (size_t i = 1; i < path.size(); ++i) chain += " -> is a kind of " + Name(path[i]);
          chain += ", an anchor of " + a->second;
          found.emplace(a->second, CategoryMatch{a->second, chain});
          continue;
        }
        for (uint32_t h : At(s).hypernyms)
          if (parent.emplace(h, s).second) queue.push_back(h);
      }
    }
    if (!found.empty()) return Values(found);
    for (uint32_t root : roots) {
      // Down, a little: a broader noun names the categories just below it.
      std::vector<std::pair<uint32_t, int>> frontier = {{root, 0}};
      std::map<uint32_t, uint32_t> parent = {{root, root}};
      for (size_t i = 0; i < frontier.size(); ++i) {
        const auto [s, depth] = frontier[i];
        if (auto a = anchor_category.find(s); a != anchor_category.end() && s != root) {
          if (!found.count(a->second)) {
            std::string chain = shown + " = " + Name(root);
            std::vector<uint32_t> path;
            for (uint32_t p = s; p != root; p = parent.at(p)) path.push_back(p);
            std::reverse(path.begin(), path.end());
            for (uint32_t p : path) chain += " -> includes " + Name(p);
            chain += ", an anchor of " + a->second;
            found.emplace(a->second, CategoryMatch{a->second, chain});
          }
          continue;
        }
        if (depth == kMaxBroaderDepth) continue;
        for (uint32_t h : At(s).hyponyms)
          if (parent.emplace(h, s).second) frontier.push_back({h, depth + 1});
      }
    }
    // A broader noun names a group: one category among its many kinds is not what it means ("vehicle" holds a
    // road roller directly, beside thirty other kinds).
    if (found.size() < 2) return {};
    return Values(found);
  }

  static std::vector<CategoryMatch> Values(const std::map<std::string, CategoryMatch>& by_category) {
    std::vector<CategoryMatch> v;
    for (const auto& [c, m] : by_category) v.push_back(m);
    return v;
  }

  // What a phrase (WordNet form) is, if anything: a category's name, a road word, or a WordNet lemma.
  std::optional<LexicalMatch> Known(const std::string& phrase) const {
    std::string spaced = phrase;
    std::replace(spaced.begin(), spaced.end(), '_', ' ');
    std::string joined = phrase;
    joined.erase(std::remove(joined.begin(), joined.end(), '_'), joined.end());
    for (const std::string& form : {spaced, phrase, joined})
      if (const auto c = FindCategory(form))
        return LexicalMatch{spaced, "category name", {{c->name, "'" + spaced + "' is a name of " + c->name}}, true};
    for (const RoadWord& r : kRoadWords)
      if (phrase == r.phrase)
        return LexicalMatch{spaced, "road word", {{r.category, "'" + spaced + "' is a road word for " + r.category +
                                                                   " (SynthDrive's list of words WordNet lacks)"}}};
    if (wordnet && senses.count(phrase)) return LexicalMatch{spaced, "WordNet", Relate(phrase)};
    return std::nullopt;
  }

  // The head: the longest final run of words that is known, its last word in each of its base forms.
  std::optional<LexicalMatch> Head(const std::vector<std::string>& words) const {
    for (size_t from = 0; from < words.size(); ++from) {
      const std::string front = JoinWords(std::vector<std::string>(words.begin() + static_cast<long>(from), words.end() - 1), 0, "_");
      for (const std::string& last : Bases(words.back())) {
        const std::string phrase = front.empty() ? last : front + "_" + last;
        if (auto m = Known(phrase)) return m;
      }
    }
    return std::nullopt;
  }
};

Lexicon::Lexicon() : impl_(std::make_unique<Impl>()) {}
Lexicon::~Lexicon() = default;
Lexicon::Lexicon(Lexicon&&) noexcept = default;
Lexicon& Lexicon::operator=(Lexicon&&) noexcept = default;

Lexicon Lexicon::Load(const fs::path& dir) {
  Lexicon lex;
  Impl& m = *lex.impl_;
  if (dir.empty() || !fs::exists(dir / "index.noun") || !fs::exists(dir / "data.noun")) return lex;
  {
    const fs::path path = dir / "index.noun";
    std::ifstream in(path);
    if (!in) throw InputError(path, "cannot be read");
    std::string line;
    int line_no = 0;
    while (std::getline(in, line)) {
      ++line_no;
      if (line.empty() || line[0] == ' ') continue;  // the licence header
      std::istringstream ls(line);
      std::string lemma, pos;
      int synset_count = 0, pointer_count = 0;
      if (!(ls >> lemma >> pos >> synset_count >> pointer_count) || pos != "n" || synset_count <= 0 || pointer_count < 0)
        throw InputError(path, Msg() << "line " << line_no << ": not an index entry (lemma n synset_cnt p_cnt ...)");
      std::string skip;
      for (int i = 0; i < pointer_count + 2; ++i) ls >> skip;  // the pointer symbols, sense_cnt, tagsense_cnt
      std::vector<uint32_t> offsets;
      uint32_t o = 0;
      while (ls >> o) offsets.push_back(o);
      if (static_cast<int>(offsets.size()) != synset_count)
        throw InputError(path, Msg() << "line " << line_no << ": '" << lemma << "' lists " << offsets.size() << " synsets, not "
                                     << synset_count);
      m.senses.emplace(lemma, std::move(offsets));
    }
    if (m.senses.empty()) throw InputError(path, "holds no entries");
  }
  {
    m.data_path = dir / "data.noun";
    std::ifstream in(m.data_path, std::ios::binary);
    if (!in) throw InputError(m.data_path, "cannot be read");
    std::ostringstream ss;
    ss << in.rdbuf();
    m.data = ss.str();
  }
  if (std::ifstream exc(dir / "noun.exc"); exc) {
    std::string line;
    while (std::getline(exc, line)) {
      if (line.empty() || line[0] == ' ') continue;  // a licence header, where there is one
      std::istringstream ls(line);
      std::string inflected, base;
      if (ls >> inflected >> base) m.exceptions.emplace(inflected, base);
    }
  }
  m.wordnet = true;
  for (const Anchor& a : kAnchors) {
    auto it = m.senses.find(a.lemma);
    if (it == m.senses.end() || a.sense < 1 || a.sense > static_cast<int>(it->second.size()))
      throw InputError(dir / "index.noun", Msg() << "has no sense " << a.sense << " of '" << a.lemma
                                                 << "' (is it WordNet 3.0?)");
    m.anchor_category.emplace(it->second[static_cast<size_t>(a.sense - 1)], a.category);
  }
  return lex;
}

bool Lexicon::has_wordnet() const { return impl_->wordnet; }

LexicalMatch Lexicon::Match(const std::string& prompt) const {
  const std::vector<std::string> words = PromptWords(prompt);
  if (words.empty()) return {};
  if (auto m = impl_->Head(words)) return *m;
  // Nothing known: the head word within one edit (a deletion, transposition, substitution or insertion), if
  // exactly the variants that are known agree on what they name.
  // Short words are left alone: one edit from a four-letter word reaches too many others ("trk" -> "turk").
  const std::string& last = words.back();
  if (last.size() < kMinEditedLength) return LexicalMatch{JoinWords(words, 0, " "), "unknown", {}};
  std::set<std::string> variants;
  const std::string letters = "abcdefghijklmnopqrstuvwxyz-";
  for (size_t i = 0; i <= last.size(); ++i) {
    if (i < last.size()) variants.insert(last.substr(0, i) + last.substr(i + 1));
    if (i + 1 < last.size()) variants.insert(last.substr(0, i) + last[i + 1] + last[i] + last.substr(i + 2));
    for (char c : letters) {
      if (i < last.size()) variants.insert(last.substr(0, i) + c + last.substr(i + 1));
      variants.insert(last.substr(0, i) + c + last.substr(i));
    }
  }
  variants.erase(last);
  std::optional<LexicalMatch> best;
  for (const std::string& v : variants) {
    if (v.empty()) continue;
    std::vector<std::string> corrected = words;
    corrected.back() = v;
    auto m = impl_->Head(corrected);
    if (!m || m->matches.empty()) continue;
    if (best) {  // two corrections that name different things: too uncertain to pick one
      std::set<std::string> a, b;
      for (const auto& x : best->matches) a.insert(x.category);
      for (const auto& x : m->matches) b.insert(x.category);
      if (a != b) return LexicalMatch{JoinWords(words, 0, " "), "unknown; corrections disagree", {}};
      continue;
    }
    m->how += ", one edit from '" + last + "'";
    m->category_name = false;  // the name is the correction's, not the prompt's
    best = std::move(m);
  }
  if (best) return *best;
  return LexicalMatch{JoinWords(words, 0, " "), "unknown", {}};
}

}  // namespace sd::mining
