// spml check-plugin LIB... [--json]: the contract suite (spml/check_plugin.h) on each library.
// One line per clause; exit 1 when any clause fails (a crashing plugin fails its clause).
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "commands.h"
#include "spml/check_plugin.h"
#include "spml/parse.h"

namespace spml::cli {
namespace {

// Each plugin is checked in a child process, so that a plugin that crashes fails the clause it
// crashed in and the checker goes on with the next, its summary and --json intact. The
// child sends every finished clause to the parent as one JSON line; its crash handler sends the
// clause that was running.
int g_clause_fd = -1;

void write_all(int fd, const std::string& text) {
  for (size_t done = 0; done < text.size();) {
    const ssize_t n = write(fd, text.data() + done, text.size() - done);
    if (n <= 0) return;
    done += static_cast<size_t>(n);
  }
}

void on_crash(int sig) {
  const char* clause = check::running_clause();
  const char head[] = "{\"crashed\":\"";
  (void)!write(g_clause_fd, head, sizeof head - 1);
  for (const char* c = clause; *c; ++c)   // clause names are plain words; keep the line valid JSON
    if (*c != '"' && *c != '\\') (void)!write(g_clause_fd, c, 1);
  (void)!write(g_clause_fd, "\"}\n", 3);
  signal(sig, SIG_DFL);
  raise(sig);
}

check::Verdict verdict_of(const std::string& word) {
  return word == "PASS" ? check::Verdict::kPass : word == "FAIL" ? check::Verdict::kFail : check::Verdict::kSkip;
}

// One child: a library, or one plugin of it (options.only_plugin).
struct Job {
  std::string file;
  check::CheckOptions options;
  pid_t pid = -1;
  int fd = -1;
  std::string text;   // the clause lines it sent
  int status = 0;
};

// Forks the child that runs check_library(job.file) and sends its clause lines.
void start(Job& job) {
  int fds[2];
  if (pipe(fds) != 0) throw std::runtime_error("check-plugin: cannot create a pipe");
  std::cout.flush();
  job.pid = fork();
  if (job.pid < 0) throw std::runtime_error("check-plugin: cannot fork");
  if (job.pid == 0) {
    close(fds[0]);
    g_clause_fd = fds[1];
    for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) signal(sig, on_crash);
    job.options.on_clause = [](const check::Clause& c) {
      check::LibraryReport one;
      one.clauses.push_back(c);
      write_all(g_clause_fd, check::to_json(one)["clauses"][0].dump() + "\n");
    };
    const check::LibraryReport r = check::check_library(job.file, job.options);
    write_all(g_clause_fd, nlohmann::json{{"kind", r.kind}, {"seconds", r.seconds}}.dump() + "\n");
    _exit(0);
  }
  close(fds[1]);
  job.fd = fds[0];
}

// The report a finished child sent, rebuilt from its clause lines (a crash named by the clause
// that was running, an abnormal end as a failed "process" clause).
check::LibraryReport report_of(const Job& job) {
  const int status = job.status;
  check::LibraryReport r;
  r.file = job.file;
  std::istringstream lines(job.text);
  for (std::string line; std::getline(lines, line);) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded()) continue;
    if (j.contains("clause"))
      r.clauses.push_back({j["plugin"], j["clause"], verdict_of(j["verdict"]), j["detail"]});
    else if (j.contains("crashed")) {   // "<plugin> <clause>"
      const std::string running = j["crashed"];
      const auto space = running.find(' ');
      r.clauses.push_back({space == std::string::npos ? "" : running.substr(0, space), running.substr(space == std::string::npos ? 0 : space + 1),
                           check::Verdict::kFail,
                           "the plugin crashed (signal " + std::to_string(WIFSIGNALED(status) ? WTERMSIG(status) : 0) + ")"});
    }
    else if (j.contains("kind"))
      r.kind = j["kind"], r.seconds = j["seconds"];
  }
  if (!(WIFEXITED(status) && WEXITSTATUS(status) == 0) && (r.clauses.empty() || r.clauses.back().detail.rfind("the plugin crashed", 0) != 0))
    r.clauses.push_back({"", "process", check::Verdict::kFail, "the check ended abnormally (status " + std::to_string(status) + ")"});
  return r;
}

// Runs the jobs, at most `parallel` children at a time, reading every running child's pipe as
// it writes (a full pipe would stop a child).
void run_jobs(std::vector<Job>& jobs, size_t parallel) {
  size_t next = 0, running = 0;
  std::vector<Job*> active;
  while (next < jobs.size() || running > 0) {
    while (running < parallel && next < jobs.size()) {
      start(jobs[next]);
      active.push_back(&jobs[next++]);
      ++running;
    }
    std::vector<pollfd> fds;
    for (Job* j : active) fds.push_back({j->fd, POLLIN, 0});
    if (poll(fds.data(), fds.size(), -1) < 0 && errno != EINTR) throw std::runtime_error("check-plugin: poll failed");
    for (size_t k = 0; k < fds.size(); ++k) {
      if (!(fds[k].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      Job* j = active[k];
      char buf[4096];
      const ssize_t n = read(j->fd, buf, sizeof buf);
      if (n > 0) {
        j->text.append(buf, static_cast<size_t>(n));
        continue;
      }
      close(j->fd);
      j->fd = -1;
      waitpid(j->pid, &j->status, 0);
      --running;
    }
    active.erase(std::remove_if(active.begin(), active.end(), [](Job* j) { return j->fd < 0; }), active.end());
  }
}

// Every library's report: each plugin checked in a child of its own, two children at a time
// (the 2-core reference machine); the library's own clauses are taken from its first child.
std::vector<check::LibraryReport> check_all(const std::vector<std::string>& files, const check::CheckOptions& options) {
  std::vector<Job> jobs;
  std::vector<std::pair<size_t, size_t>> range;   // per file: its jobs [first, last)
  for (const auto& f : files) {
    const size_t first = jobs.size();
    const auto names = check::plugin_names(f);
    auto add = [&](const std::string& only) {
      Job j;
      j.file = f;
      j.options = options;
      j.options.only_plugin = only;
      jobs.push_back(std::move(j));
    };
    if (names.empty()) add("");
    for (const auto& n : names) add(n);
    range.emplace_back(first, jobs.size());
  }
  run_jobs(jobs, 2);
  std::vector<check::LibraryReport> out;
  for (size_t i = 0; i < files.size(); ++i) {
    check::LibraryReport r;
    r.file = files[i];
    for (size_t k = range[i].first; k < range[i].second; ++k) {
      const check::LibraryReport part = report_of(jobs[k]);
      for (const auto& c : part.clauses)
        if (k == range[i].first || !c.plugin.empty() || c.name == "process") r.clauses.push_back(c);
      if (r.kind.empty()) r.kind = part.kind;
      r.seconds += part.seconds;
    }
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace

void add_check_plugin(CLI::App& app) {
  auto* cmd = app.add_subcommand("check-plugin", "Run the plugin contract suite on learner or force-plugin libraries");
  auto files = std::make_shared<std::vector<std::string>>();
  auto json = std::make_shared<bool>(false);
  auto seed = std::make_shared<std::string>("1");
  cmd->add_option("LIB", *files, "Plugin library files (.so), learner or force plugin")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--json", *json, "Print one JSON document instead of lines");
  cmd->add_option("--seed", *seed, "Seed of the synthetic data and states (default 1)");
  auto sets = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--set", *sets, "KEY=VALUE for every plugin that has the key (e.g. steps=300 for a faster BNN check); repeatable")
      ->expected(1)
      ->allow_extra_args(false);
  cmd->callback([=] {
    check::CheckOptions options;
    options.seed = seed_option("--seed", *seed);
    for (const auto& kv : *sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) throw CLI::ValidationError("--set", "'" + kv + "': expected key=value");
      options.config.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    std::vector<std::string> absolute;
    for (const auto& f : *files) absolute.push_back(std::filesystem::absolute(f).string());
    if (std::string why = check::config_problem(absolute, options.config); !why.empty()) throw CLI::ValidationError("--set", why);
    const auto t0 = std::chrono::steady_clock::now();
    nlohmann::json libraries = nlohmann::json::array();
    int failed = 0, clauses = 0;
    for (const check::LibraryReport& r : check_all(absolute, options)) {
      if (!*json) std::cout << r.file << std::endl;
      for (const auto& c : r.clauses) {
        if (!*json) std::cout << "  " << check::clause_line(c) << "\n";
        ++clauses;
        if (c.verdict == check::Verdict::kFail) ++failed;
      }
      if (*json) libraries.push_back(check::to_json(r));
      else std::cout << "  " << (r.passed() ? "passed" : "FAILED") << " (" << (r.kind.empty() ? "kind unknown" : r.kind) << ", " << number_text(r.seconds, 3) << " s)\n";
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (*json)
      std::cout << nlohmann::json{{"libraries", libraries}, {"clauses", clauses}, {"failed", failed}, {"seconds", seconds}}.dump(2) << "\n";
    else
      std::cout << files->size() << " libraries, " << clauses << " clauses, " << failed << " failed, in " << number_text(seconds, 3) << " s\n";
    if (failed) throw std::runtime_error("check-plugin: " + std::to_string(failed) + " of " + std::to_string(clauses) + " clauses failed");
  });
}

}  // namespace spml::cli
