//! Property tests of the LED protocol: any command, encoded as a line and decoded as the
//! device decodes it, is the same command; any reply likewise; any valid configuration
//! is accepted, and a configuration out of range is refused with RANGE.

use proptest::prelude::*;
use rollcam_hw::led::protocol::{
    decode_frame, encode_frame, Command, Reply, CHANNELS, MAX_COUNT, MAX_LINE, MAX_PERIOD_US, MAX_PHASE_US, MIN_PERIOD_US, MIN_WIDTH_US,
};
use rollcam_hw::led::{ChannelConfig, ErrorCode, TriggerMode};

fn config() -> impl Strategy<Value = ChannelConfig> {
    (MIN_PERIOD_US..=MAX_PERIOD_US, 0.0f64..1.0, 0..=MAX_PHASE_US, prop::option::of(1..=MAX_COUNT)).prop_map(|(period, f, phase, count)| {
        let width = MIN_WIDTH_US + ((period - 2 * MIN_WIDTH_US) as f64 * f) as u32;
        ChannelConfig { period_us: period, width_us: width, phase_us: phase, pulse_count: count }
    })
}

fn command() -> impl Strategy<Value = Command> {
    let channel = 0..CHANNELS;
    let mode = prop::sample::select(vec![TriggerMode::Software, TriggerMode::Rising, TriggerMode::Falling]);
    prop_oneof![
        Just(Command::Identify),
        (channel.clone(), config()).prop_map(|(channel, config)| Command::Configure { channel, config }),
        channel.clone().prop_map(|channel| Command::Off { channel }),
        channel.prop_map(|channel| Command::Get { channel }),
        mode.prop_map(Command::Arm),
        Just(Command::Trigger),
        Just(Command::Stop),
        Just(Command::Status),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn a_command_encoded_and_parsed_is_the_same_command(cmd in command(), seq in 1u16..=u16::MAX) {
        let line = encode_frame(seq, &cmd.to_body());
        prop_assert!(line.len() <= MAX_LINE, "{} bytes: {}", line.len(), line);
        let frame = decode_frame(line.as_bytes()).unwrap();
        prop_assert_eq!(frame.seq, seq);
        prop_assert_eq!(Command::parse(&frame.body), Ok(cmd));
    }

    #[test]
    fn a_reply_encoded_and_parsed_is_the_same_reply(
        payload in "[a-z_]{1,8}=[A-Za-z0-9.-]{0,8}( [a-z_]{1,8}=[0-9]{1,6}){0,5}",
        code in prop::sample::select(ErrorCode::ALL.to_vec()),
        ack in any::<bool>(),
        seq in 0u16..=u16::MAX,
    ) {
        let reply = if ack { Reply::Ack(payload) } else { Reply::Nak(code) };
        let frame = decode_frame(encode_frame(seq, &reply.to_body()).as_bytes()).unwrap();
        prop_assert_eq!(frame.seq, seq);
        prop_assert_eq!(Reply::parse(&frame.body), Some(reply));
    }

    #[test]
    fn a_configuration_out_of_range_is_refused_with_range(
        channel in 0u32..8,
        period in prop_oneof![0u32..MIN_PERIOD_US, MIN_PERIOD_US..=MAX_PERIOD_US, MAX_PERIOD_US..=u32::MAX],
        width in any::<u32>(),
        phase in prop_oneof![0..=MAX_PHASE_US, MAX_PHASE_US..=u32::MAX],
        count in prop_oneof![0..=MAX_COUNT, MAX_COUNT..=u32::MAX],
    ) {
        let cfg = ChannelConfig { period_us: period, width_us: width, phase_us: phase, pulse_count: (count > 0).then_some(count) };
        let body = format!("CFG {channel} {period} {width} {phase} {count}");
        let parsed = Command::parse(&body);
        if channel < u32::from(CHANNELS) && cfg.validate().is_ok() {
            prop_assert_eq!(parsed, Ok(Command::Configure { channel: channel as u8, config: cfg }));
        } else {
            prop_assert_eq!(parsed, Err(ErrorCode::Range));
        }
    }
}
