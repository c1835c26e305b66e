#pragma once
// The CLI is a table of subcommands over library calls (STYLE.md habit 13). Each command file registers its
// options on a CLI11 subcommand and returns the function that runs it; the library never sees argv.
#include <functional>
#include <string>

namespace CLI {
class App;
}

namespace sd::cli {

using Runner = std::function<int()>;

Runner AddSynthCommand(CLI::App& app);
Runner AddAssetCommand(CLI::App& app);
Runner AddDemoCommand(CLI::App& app);
Runner AddCategoriesCommand(CLI::App& app);
Runner AddRefineCommand(CLI::App& app);
Runner AddViewsCommand(CLI::App& app);
Runner AddEvalCommand(CLI::App& app);
Runner AddTextureCommand(CLI::App& app);
Runner AddUpscaleCommand(CLI::App& app);
Runner AddGenerateCommand(CLI::App& app);
Runner AddMineCommand(CLI::App& app);
Runner AddBankCommand(CLI::App& app);
Runner AddSlurmCommand(CLI::App& app);

// The repo's data/ directory: --data, $SYNTHDRIVE_DATA, <binary>/../../data, ./data (first that exists).
std::string FindDataDir(const std::string& explicit_dir);

}  // namespace sd::cli
