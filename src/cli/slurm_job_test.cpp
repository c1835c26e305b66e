#include "cli/slurm_job.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"

namespace sd::cli {
namespace {

namespace fs = std::filesystem;

SlurmJobSpec MineSpec() {
  SlurmJobSpec s;
  s.binary = "/opt/sd/bin/synthdrive";
  s.command = {"mine", "index", "--log", "data/my log.json", "--out", "idx", "--clip", "none"};
  s.shards = 4;
  s.cpus_per_task = 3;
  s.job_name = "sd-mine";
  s.log_dir = "/shared/logs";
  s.work_dir = "/home/me/it's here";
  return s;
}

bool Contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(SlurmJob, ScriptHasArrayLogsThreadsAndQuotedCommand) {
  SlurmJobSpec s = MineSpec();
  s.partition = "cpu";
  s.time = "2:00:00";
  s.mem = "16G";
  s.sbatch_args = {"--account=perception", "--exclusive"};
  const std::string script = MakeSlurmScript(s);
  EXPECT_EQ(script.rfind("#!/bin/bash\n", 0), 0u);
  for (const char* line : {"#SBATCH --job-name=sd-mine\n", "#SBATCH --array=0-3\n",
                           "#SBATCH --output=/shared/logs/sd-mine-%A_%a.out\n", "#SBATCH --cpus-per-task=3\n",
                           "#SBATCH --partition=cpu\n", "#SBATCH --time=2:00:00\n", "#SBATCH --mem=16G\n",
                           "#SBATCH --account=perception\n", "#SBATCH --exclusive\n", "\nset -euo pipefail\n",
                           "\ncd '/home/me/it'\\''s here'\n"})
    EXPECT_TRUE(Contains(script, line)) << line << " missing from\n" << script;
  EXPECT_TRUE(Contains(script, "\nexec /opt/sd/bin/synthdrive --threads 3 mine index --log 'data/my log.json' --out idx "
                               "--clip none --shard \"${SLURM_ARRAY_TASK_ID}/4\"\n"))
      << script;
  // sbatch stops reading #SBATCH lines at the first command: all of them must come before `set`.
  EXPECT_LT(script.rfind("#SBATCH"), script.find("set -euo"));
}

TEST(SlurmJob, OptionalSettingsAreLeftToTheSite) {
  const std::string script = MakeSlurmScript(MineSpec());
  EXPECT_FALSE(Contains(script, "--partition"));
  EXPECT_FALSE(Contains(script, "--time"));
  EXPECT_FALSE(Contains(script, "--mem"));
}

// The script, run by bash as Slurm would (SLURM_ARRAY_TASK_ID set), hands the binary exactly our arguments.
TEST(SlurmJob, ScriptRunsTheBinaryWithItsShard) {
  const fs::path dir = fs::temp_directory_path() / ("slurm_job_test_" + std::to_string(::getpid()));
  fs::create_directories(dir / "work dir");
  const fs::path fake = dir / "fake synthdrive";
  {
    std::ofstream f(fake);
    f << "#!/bin/bash\npwd > \"$(dirname \"$0\")/args\"\nfor a in \"$@\"; do printf '%s\\n' \"$a\"; done >> "
         "\"$(dirname \"$0\")/args\"\n";
  }
  fs::permissions(fake, fs::perms::owner_all);
  SlurmJobSpec s = MineSpec();
  s.binary = fake;
  s.work_dir = dir / "work dir";
  s.log_dir = dir;
  const fs::path script = dir / "job.sbatch";
  std::ofstream(script) << MakeSlurmScript(s);
  const std::string cmd = "SLURM_ARRAY_TASK_ID=2 SLURM_ARRAY_JOB_ID=7 bash '" + script.string() + "' 2>/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream in(dir / "args");
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all, (dir / "work dir").string() +
                     "\n--threads\n3\nmine\nindex\n--log\ndata/my log.json\n--out\nidx\n--clip\nnone\n--shard\n2/4\n");
  // Without Slurm's variable the script refuses instead of running shard "/4".
  const std::string bare = "env -u SLURM_ARRAY_TASK_ID bash '" + script.string() + "' 2>/dev/null";
  EXPECT_NE(std::system(bare.c_str()), 0);
  fs::remove_all(dir);
}

TEST(SlurmJob, AllowsOnlyBatchCommandsWithoutShard) {
  EXPECT_NO_THROW(CheckShardableCommand({"mine", "index", "--out", "x"}));
  EXPECT_NO_THROW(CheckShardableCommand({"generate", "--manifest", "m.jsonl", "--out", "x"}));
  EXPECT_NO_THROW(CheckShardableCommand({"generate", "--manifest=m.jsonl", "--out", "x"}));
  EXPECT_NO_THROW(CheckShardableCommand({"synth", "--log", "l", "--out", "x"}));
  EXPECT_THROW(CheckShardableCommand({}), InputError);
  EXPECT_THROW(CheckShardableCommand({"mine", "query", "--index", "x"}), InputError);
  EXPECT_THROW(CheckShardableCommand({"generate", "--image", "a.png", "--out", "x"}), InputError);
  EXPECT_THROW(CheckShardableCommand({"demo"}), InputError);
  EXPECT_THROW(CheckShardableCommand({"mine", "index", "--shard", "0/2"}), InputError);
  EXPECT_THROW(CheckShardableCommand({"synth", "--shard=1/2"}), InputError);
  EXPECT_THROW(CheckShardableCommand({"synth", "--log", "l", "--out", "x", "--merge"}), InputError);
}

TEST(SlurmJob, RefusesValuesAnSbatchLineCannotCarry) {
  SlurmJobSpec s = MineSpec();
  s.log_dir = "/shared/my logs";
  EXPECT_THROW(MakeSlurmScript(s), InputError);
  s = MineSpec();
  s.mem = "16 G";
  EXPECT_THROW(MakeSlurmScript(s), InputError);
  s = MineSpec();
  s.sbatch_args = {"--array=0-9"};
  EXPECT_THROW(MakeSlurmScript(s), InputError);
  s = MineSpec();
  s.sbatch_args = {"--comment=a\n#SBATCH --x"};
  EXPECT_THROW(MakeSlurmScript(s), InputError);
  s = MineSpec();
  s.job_name = "a/b";
  EXPECT_THROW(MakeSlurmScript(s), InputError);
  s = MineSpec();
  s.shards = 0;
  EXPECT_THROW(MakeSlurmScript(s), InputError);
}

TEST(SlurmJob, ShellQuote) {
  EXPECT_EQ(ShellQuote("plain/path-1.json"), "plain/path-1.json");
  EXPECT_EQ(ShellQuote(""), "''");
  EXPECT_EQ(ShellQuote("a b"), "'a b'");
  EXPECT_EQ(ShellQuote("it's"), "'it'\\''s'");
  EXPECT_EQ(ShellQuote("$HOME"), "'$HOME'");
}

TEST(SlurmJob, ParsesSbatchJobId) {
  EXPECT_EQ(ParseSbatchJobId("1234\n"), "1234");
  EXPECT_EQ(ParseSbatchJobId("77;cluster-a\n"), "77");
  EXPECT_THROW(ParseSbatchJobId(""), InputError);
  EXPECT_THROW(ParseSbatchJobId("sbatch: error: x"), InputError);
}

TEST(SlurmJob, ClassifiesSlurmStates) {
  EXPECT_EQ(ClassifySlurmState("PENDING"), TaskState::kPending);
  EXPECT_EQ(ClassifySlurmState("CONFIGURING"), TaskState::kPending);
  EXPECT_EQ(ClassifySlurmState("RUNNING"), TaskState::kRunning);
  EXPECT_EQ(ClassifySlurmState("COMPLETING"), TaskState::kRunning);
  EXPECT_EQ(ClassifySlurmState("COMPLETED"), TaskState::kCompleted);
  for (const char* s : {"FAILED", "CANCELLED by 0", "CANCELLED+", "TIMEOUT", "OUT_OF_MEMORY", "NODE_FAIL",
                        "PREEMPTED", "SOMETHING_NEW"})
    EXPECT_EQ(ClassifySlurmState(s), TaskState::kFailed) << s;
}

TEST(SlurmJob, ReadsSqueueAndSacctLines) {
  std::map<int, TaskStatus> tasks;
  // sacct: a finished task with its steps, a pending throttled range, and another job's line.
  ReadSlurmTaskLines("12_0|COMPLETED\n12_0.batch|COMPLETED\n12_[1-3,5%2]|PENDING\n120_4|FAILED\n\n", "12", tasks);
  ASSERT_EQ(tasks.size(), 5u);
  EXPECT_EQ(tasks[0].state, TaskState::kCompleted);
  for (int t : {1, 2, 3, 5}) EXPECT_EQ(tasks[t].state, TaskState::kPending) << t;
  EXPECT_EQ(tasks.count(4), 0u);
  // squeue (read last) has the newer view.
  ReadSlurmTaskLines("12_1|RUNNING\n12_2|FAILED\n12_3|CANCELLED by 0\n", "12", tasks);
  EXPECT_EQ(tasks[1].state, TaskState::kRunning);
  EXPECT_EQ(tasks[2].state, TaskState::kFailed);
  EXPECT_EQ(tasks[3].state, TaskState::kFailed);
  EXPECT_EQ(tasks[3].slurm_state, "CANCELLED by 0");
  EXPECT_EQ(tasks[5].state, TaskState::kPending);
}

TEST(SlurmJob, RunProcessCapturesOutputAndExitCode) {
  const ProcessResult r = RunProcess({"sh", "-c", "echo out; echo err >&2; exit 3"});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.out, "out\n");
  EXPECT_EQ(r.err, "err\n");
  EXPECT_EQ(RunProcess({"no-such-program-synthdrive"}).exit_code, 127);
}

}  // namespace
}  // namespace sd::cli
