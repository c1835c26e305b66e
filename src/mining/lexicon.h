#pragma once
// Prompts to categories without CLIP: the lexical path of `mine query` (docs/mining.md, "Prompts beyond labels").
//
// A prompt names a category when it is a category's name or a dataset's name for one (CategoryForPrompt), a road
// word WordNet lacks ("pylon", "witch's hat": a short list here), or a WordNet noun related to a category's anchor
// synsets: the same synset or one below it ("lorry" is a kind of truck; "bulldozer" and "road roller" are anchors
// of construction_vehicle), or one just above several ("motor vehicle" holds car, truck, motorcycle). The noun is
// the prompt's head: its longest final run of words that is known ("orange traffic cone" -> "traffic cone";
// "witch's hat" is not read as a witch). Plurals go through WordNet's own exception list and suffix rules; a head
// word known nowhere is tried within one edit ("motorcyle"). Every match carries the chain of relations, so a user
// sees why a prompt found what it found.
//
// WordNet 3.0 comes from Debian's `wordnet-base` (/usr/share/wordnet, or $SYNTHDRIVE_WORDNET); only its noun
// files are read: index.noun, data.noun (by byte offset, as the format intends) and noun.exc.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace sd::mining {

struct CategoryMatch {
  std::string category;  // canonical (datasets/categories.h)
  std::string chain;     // why, e.g. "lorry = lorry#2 (a large truck...) -> is a kind of truck#1 (anchor of truck)"
};

struct LexicalMatch {
  std::string head;                     // the prompt's words that were read ("traffic cone"), after any correction
  std::string how;                      // "category name", "road word", "WordNet", "WordNet, one edit from 'x'"
  std::vector<CategoryMatch> matches;   // empty: the prompt names no category
  bool category_name = false;           // the head, as written, is a category's own name (a label query)
};

// $SYNTHDRIVE_WORDNET, else /usr/share/wordnet.
std::filesystem::path DefaultWordNetDir();

class Lexicon {
 public:
  // Without WordNet (`wordnet_dir` empty or missing its files) the lexicon still knows the category names and the
  // road words; a WordNet file that is there but malformed is an InputError naming it.
  static Lexicon Load(const std::filesystem::path& wordnet_dir = DefaultWordNetDir());
  ~Lexicon();
  Lexicon(Lexicon&&) noexcept;
  Lexicon& operator=(Lexicon&&) noexcept;

  bool has_wordnet() const;
  LexicalMatch Match(const std::string& prompt) const;

 private:
  Lexicon();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sd::mining
